"""The RabbitHZD-v0 Gymnasium environment: API conformance, and the classic gait as an
action walks with a small tracking error."""

from __future__ import annotations

from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from rabbit_policy.learning.env import DISTRIBUTIONS, RabbitHZDEnv
from rabbit_policy.runtime.gait_library import GaitLibrary

pytestmark = pytest.mark.sim


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")  # physical units by design
def test_env_passes_the_gymnasium_checker():
    env = gym.make("RabbitHZD-v0")
    check_env(env.unwrapped, skip_render_check=True)
    assert env.observation_space.shape == (3,) and env.action_space.shape == (21,)


@pytest.mark.parametrize("imports", ["import rabbit_policy; import gymnasium",
                                     "import gymnasium; import rabbit_policy"])
def test_gymnasium_makes_the_env_after_import_rabbit_policy_and_policy_node_pays_nothing(imports):
    """``gymnasium.make("RabbitHZD-v0")`` after ``import rabbit_policy``, in either import
    order, in a fresh interpreter; importing policy_node imports neither Gymnasium nor the
    env module (the id is registered by entry-point string when Gymnasium is imported)."""
    import subprocess
    import sys

    code = ("import sys; import rabbit_policy.policy_node; "
            "assert 'gymnasium' not in sys.modules and 'rabbit_policy.learning.env' not in sys.modules; "
            f"{imports}; env = gymnasium.make('RabbitHZD-v0'); env.reset(seed=0); "
            "print(type(env.unwrapped).__name__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["RabbitHZDEnv"]


def test_classic_gaits_lie_inside_the_action_bounds():
    env = RabbitHZDEnv()
    for gait in GaitLibrary.load().gaits:
        action = np.append(gait.free, gait.kd)
        assert np.all(action >= env.bounds.low) and np.all(action <= env.bounds.high)


def test_library_gait_as_action_walks_and_tracks():
    env = RabbitHZDEnv(max_steps=30)
    obs, info = env.reset(seed=3)
    library = GaitLibrary.load()
    rewards, last = [], None
    for _ in range(30):
        gait = library.nearest(info["desired_speed"])
        obs, reward, terminated, truncated, info = env.step(np.append(gait.free, gait.kd).astype(np.float32))
        rewards.append(reward)
        assert not info["rejected"]
        if terminated or truncated:
            last = (terminated, truncated)
            break
    assert last == (False, True)  # walked the whole episode
    assert np.mean(rewards[-5:]) > -0.02  # within ~0.14 m/s of the command on average


def test_a_bad_action_is_rejected_and_the_episode_goes_on():
    # inside the bounds every waypoint set is a valid gait (the bounds keep stance and swing
    # hips apart at the switch); a non-finite action is what the controller must refuse
    env = RabbitHZDEnv(max_steps=5)
    env.reset(seed=0)
    action = np.full(21, np.nan, dtype=np.float32)
    _obs, _r, terminated, _t, info = env.step(action)
    assert info["rejected"] and not terminated


def test_determinism_for_a_seed():
    def rollout():
        env = RabbitHZDEnv(max_steps=5)
        env.reset(seed=7)
        out = []
        for _ in range(5):
            out.append(env.step(np.full(21, 0.5, np.float32) * (env.bounds.low + env.bounds.high))[:2])
        return out
    a, b = rollout(), rollout()
    assert all(np.array_equal(x[0], y[0]) and x[1] == y[1] for x, y in zip(a, b))


@pytest.mark.slow
def test_warm_started_network_reproduces_the_library_and_walks():
    from rabbit_policy.runtime.network import HZDPolicyNet, act
    from rabbit_policy.runtime.speed_window import Observation
    from dataclasses import replace

    from rabbit_policy.learning.warm_start import WARM_STARTS, library_targets, warm_start

    env = RabbitHZDEnv(max_steps=20)
    net = HZDPolicyNet(env.bounds.low, env.bounds.high)
    warm_start(net, env.library, seed=0, config=replace(WARM_STARTS["scheduled"], iterations=4000))
    for v in (0.8, 1.0, 1.4):  # away from the steps of the nearest-gait staircase (and v + 0.3 too)
        error = np.abs(act(net, Observation(v, v, 0.0)) - library_targets(env.library, np.array([v]))[0])
        assert error[:20].max() < 0.06  # rad (a fit: its last digits vary with torch threads)
        # measured 0.5 m/s above the command: the gait 0.2 m/s below the measured speed
        error = np.abs(act(net, Observation(v, v + 0.5, -0.5)) - library_targets(
            env.library, np.array([v]), np.array([v + 0.5]))[0])
        assert error[:20].max() < 0.05  # rad
    obs, _info = env.reset(seed=2)
    for _ in range(20):
        obs, _r, terminated, truncated, info = env.step(act(net, Observation(*obs.astype(float))).astype(np.float32))
        assert not terminated and not info["rejected"]
    assert truncated


def test_es_generation_is_deterministic_for_a_seed_and_worker_count():
    from rabbit_policy.learning.es import ESConfig, EvolutionStrategy, centred_ranks
    from rabbit_policy.runtime.network import HZDPolicyNet

    assert np.allclose(centred_ranks(np.array([3.0, -1.0, 2.0])), [0.5, -0.5, 0.0])
    bounds = RabbitHZDEnv().bounds
    thetas = []
    for _ in range(2):
        import torch

        torch.manual_seed(0)
        es = EvolutionStrategy(HZDPolicyNet(bounds.low, bounds.high),
                               ESConfig(pairs=2, episodes=1, max_steps=3, workers=2, seed=5))
        try:
            stats = es.step()
        finally:
            es.close()
        thetas.append(es.theta)
        assert stats["env_steps"] > 0
    assert np.array_equal(thetas[0], thetas[1])


def test_decisions_every_n_ticks_step_the_env_by_n_ticks_and_apply_at_once():
    env = RabbitHZDEnv(max_steps=60, decision_period=20)
    env.reset(seed=0, options={"desired_speed": 1.0, "next_speed": 1.0})
    gait = env.library.nearest(1.0)
    other = env.library.nearest(1.2)
    start = env.loop.ticks
    obs, _, terminated, _, info = env.step(np.append(gait.free, gait.kd))
    assert env.loop.ticks - start == 20 and not terminated
    obs, _, _, _, info = env.step(np.append(other.free, other.kd))
    assert env.loop.controller.alpha == tuple(other.alpha)  # at once, not at the next touchdown
    assert env.loop.controller.pending_alpha is None
    with pytest.raises(ValueError):
        RabbitHZDEnv(decision_period=-1)


def test_broad_episodes_draw_commands_pushes_models_and_delays():
    env = RabbitHZDEnv(max_steps=500, decision_period=20, distribution="broad")
    drawn = []
    for seed in range(12):
        env.reset(seed=seed)
        drawn.append(env.loop.scenario)
    for scenario in drawn:
        times = [t for t, _ in scenario.schedule]
        assert all(2.0 - 1e-9 <= b - a <= 5.0 + 1e-9 for a, b in zip(times, times[1:]))
        assert all(0.7 <= v <= 1.5 for _, v in scenario.schedule)
        assert all(abs(p.impulse) <= 15.0 + 1e-9 for p in scenario.pushes)
    assert any(s.pushes for s in drawn) and any(not s.pushes for s in drawn)
    assert {s.model.variant for s in drawn} == {"paper", "drives"}
    assert len({s.torque_delay for s in drawn}) > 1 and len({s.model.friction for s in drawn}) > 1
    again = RabbitHZDEnv(max_steps=500, decision_period=20, distribution="broad")
    again.reset(seed=3)
    assert again.loop.scenario == drawn[3]  # seeded


def test_robust_episodes_add_noise_to_the_measured_inputs_only_and_reward_the_true_speed():
    noisy = RabbitHZDEnv(max_steps=500, decision_period=20, distribution="robust")
    clean = RabbitHZDEnv(max_steps=500, decision_period=20,
                         distribution=replace(DISTRIBUTIONS["robust"], observation_noise=0.0))
    obs_noisy, _ = noisy.reset(seed=5)
    obs_clean, _ = clean.reset(seed=5)
    assert obs_noisy[0] == obs_clean[0]  # the command is not measured: no noise
    assert not np.allclose(obs_noisy[1:], obs_clean[1:])
    action = (noisy.bounds.low + noisy.bounds.high) / 2
    for _ in range(3):
        _, reward_noisy, _, _, info_noisy = noisy.step(action)
        _, reward_clean, _, _, info_clean = clean.step(action)
        assert reward_noisy == reward_clean and info_noisy["mean_speed"] == info_clean["mean_speed"]
