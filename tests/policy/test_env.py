"""The RabbitHZD-v0 Gymnasium environment: API conformance, and the classic gait as an
action walks with a small tracking error."""

from __future__ import annotations

import os
import warnings
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from rabbit_policy.learning.env import RabbitHZDEnv
from rabbit_policy.runtime.gait_library import GaitLibrary

pytestmark = pytest.mark.sim


def test_env_passes_the_gymnasium_and_sb3_checkers_with_no_warning():
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("RabbitHZD-v0")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any checker warning fails the test
        check_env(env.unwrapped, skip_render_check=True)
        sb3_check_env(RabbitHZDEnv(max_steps=5), warn=True, skip_render_check=True)
    assert env.observation_space.shape == (3,) and env.action_space.shape == (21,)
    assert env.action_space.low.min() == -1.0 and env.action_space.high.max() == 1.0
    assert env.spec.max_episode_steps == 60


def test_normalised_actions_map_onto_the_physical_bounds():
    bounds = RabbitHZDEnv().bounds
    assert np.allclose(bounds.to_physical(-np.ones(21)), bounds.low)
    assert np.allclose(bounds.to_physical(np.ones(21)), bounds.high)
    assert np.allclose(bounds.to_physical(np.full(21, 7.0)), bounds.high)  # clipped
    x = bounds.low + 0.3 * (bounds.high - bounds.low)
    assert np.allclose(bounds.to_physical(bounds.to_normalised(x)), x, atol=1e-12)


def test_the_episode_length_is_the_specs_max_episode_steps():
    env = gym.make("RabbitHZD-v0", max_steps=3, max_episode_steps=3, decision_period=20)
    env.reset(seed=0)
    ends = [env.step(np.zeros(21, np.float32))[2:4] for _ in range(3)]
    assert ends == [(False, False), (False, False), (False, True)]
    assert gym.spec("RabbitHZD-v0").max_episode_steps == RabbitHZDEnv().max_steps == 60


def test_reward_terms_are_in_info_and_sum_to_the_reward():
    env = RabbitHZDEnv(max_steps=60, decision_period=20)
    env.reset(seed=1)
    _obs, reward, _te, _tr, info = env.step(np.zeros(21, np.float32))
    assert reward == info["reward_tracking"] + info["reward_fall"] and info["reward_fall"] == 0.0
    assert info["reward_alive"] == info["reward_slow"] == 0.0  # no survival or slow-hip term by default
    assert info["reward_tracking"] == -((info["mean_speed"] - info["desired_speed"]) ** 2)
    falling = RabbitHZDEnv(max_steps=60, decision_period=20, fall_penalty=-7.0)
    falling.reset(seed=1)
    for _ in range(60):  # the lowest coefficients and Kd everywhere: RABBIT collapses
        _obs, reward, terminated, _tr, info = falling.step(-np.ones(21, np.float32))
        if terminated:
            break
    assert terminated and info["reward_fall"] == -7.0 and reward == info["reward_tracking"] - 7.0


def test_render_mode_is_checked_and_rendering_without_one_warns():
    with pytest.raises(ValueError, match="render_mode"):
        RabbitHZDEnv(render_mode="video")
    env = RabbitHZDEnv()
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


RENDER_CHECK = """
import gymnasium, numpy as np, rabbit_policy
from gymnasium.utils.env_checker import check_env
env = gymnasium.make('RabbitHZD-v0', render_mode='rgb_array', decision_period=20)
env.reset(seed=0)
first = env.render()
for _ in range(10):
    env.step(np.zeros(21, np.float32))
later = env.render()
assert first.shape == (240, 320, 3) and first.dtype == np.uint8, first.shape
assert np.abs(first.astype(int) - later).mean() > 0.5  # the camera follows a walking robot
assert env.metadata['render_fps'] == 50
env.close()
if {full}:  # every render mode (human: MuJoCo's viewer), no warning
    import warnings
    warnings.simplefilter('error')
    check_env(gymnasium.make('RabbitHZD-v0').unwrapped)
print('ok')
"""


@pytest.mark.slow
def test_rgb_array_renders_offscreen_and_the_checker_passes_every_render_mode(display):
    """In fresh interpreters: ``rgb_array`` headless with MuJoCo's EGL backend (Mesa's software
    rasteriser, no display), then on a virtual display Gymnasium's checker with its render
    checks (``human`` opens MuJoCo's viewer), warnings as errors."""
    import subprocess
    import sys

    headless = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    on_display = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    for env, full in (({**headless, "MUJOCO_GL": "egl"}, False), ({**on_display, "DISPLAY": display}, True)):
        out = subprocess.run([sys.executable, "-c", RENDER_CHECK.format(full=full)], capture_output=True, text=True,
                             timeout=180, env=env)
        assert out.returncode == 0 and out.stdout.split() == ["ok"], out.stderr[-2000:]
    # a process that renders and exits without closing its env: no EGLError tracebacks at exit
    unclosed = ("import gymnasium, rabbit_policy; env = gymnasium.make('RabbitHZD-v0', render_mode='rgb_array'); "
                "env.reset(seed=0); env.render(); print('ok')")
    out = subprocess.run([sys.executable, "-c", unclosed], capture_output=True, text=True, timeout=180,
                         env={**headless, "MUJOCO_GL": "egl"})
    assert out.returncode == 0 and out.stdout.split() == ["ok"] and "Traceback" not in out.stderr, out.stderr[-2000:]


def test_human_rendering_without_a_display_is_one_clear_error(monkeypatch):
    from rabbit_sim.viewer import ViewerUnavailable

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    env = RabbitHZDEnv(render_mode="human")
    with pytest.raises(ViewerUnavailable, match="display"):
        env.reset(seed=0)


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
        obs, reward, terminated, truncated, info = env.step(env.bounds.to_normalised(np.append(gait.free, gait.kd)))
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
            out.append(env.step(np.zeros(21, np.float32))[:2])
        return out
    a, b = rollout(), rollout()
    assert all(np.array_equal(x[0], y[0]) and x[1] == y[1] for x, y in zip(a, b))


@pytest.mark.slow
def test_warm_started_network_reproduces_the_library_and_walks():
    from rabbit_policy.runtime.network import HZDPolicyNet, NetworkForward
    from rabbit_policy.runtime.speed_window import Observation
    from dataclasses import replace

    from rabbit_policy.learning.warm_start import WARM_STARTS, library_targets, warm_start

    env = RabbitHZDEnv(max_steps=20)
    net = HZDPolicyNet(env.bounds.low, env.bounds.high)
    warm_start(net, env.library, seed=0, config=replace(WARM_STARTS["scheduled"], iterations=4000))
    for v in (0.8, 1.0, 1.4):  # away from the steps of the nearest-gait staircase (and v + 0.3 too)
        error = np.abs(NetworkForward.of(net)(Observation(v, v, 0.0)) - library_targets(env.library, np.array([v]))[0])
        assert error[:20].max() < 0.06  # rad (a fit: its last digits vary with torch threads)
        # measured 0.5 m/s above the command: the gait 0.2 m/s below the measured speed
        error = np.abs(NetworkForward.of(net)(Observation(v, v + 0.5, -0.5)) - library_targets(
            env.library, np.array([v]), np.array([v + 0.5]))[0])
        assert error[:20].max() < 0.05  # rad
    obs, _info = env.reset(seed=2)
    for _ in range(20):
        obs, _r, terminated, truncated, info = env.step(env.bounds.to_normalised(NetworkForward.of(net)(Observation(*obs.astype(float)))))
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
    obs, _, terminated, _, info = env.step(env.bounds.to_normalised(np.append(gait.free, gait.kd)))
    assert env.loop.ticks - start == 20 and not terminated
    obs, _, _, _, info = env.step(env.bounds.to_normalised(np.append(other.free, other.kd)))
    assert np.allclose(env.loop.controller.alpha, other.alpha, atol=1e-12)  # at once, not at the next touchdown
    assert env.loop.controller.pending_alpha is None
    with pytest.raises(ValueError):
        RabbitHZDEnv(decision_period=-1)


def test_memory_features_integrate_the_speed_error_with_anti_windup_and_carry_the_last_action():
    from rabbit_policy.runtime.memory import MemoryConfig, SpeedMemory
    from rabbit_policy.runtime.speed_integral import IntegralConfig

    memory = SpeedMemory(MemoryConfig(IntegralConfig(limit=0.2, dt=0.02)))
    first = memory.inputs(np.array([1.0, 0.9, 0.1]))
    assert first.shape == (25,) and first[3] == pytest.approx(0.002) and not first[4:].any()
    memory.record(np.full(21, 0.5))
    for _ in range(200):  # a steady 0.1 m/s error: the integral stops at the bound
        x = memory.inputs(np.array([1.0, 0.9, 0.1]))
    assert x[3] == pytest.approx(0.2) and np.all(x[4:] == 0.5)
    memory.reset()
    assert memory.integral == 0.0

    env = RabbitHZDEnv(max_steps=500, decision_period=20, features="memory")
    obs, _ = env.reset(seed=0)
    assert env.observation_space.shape == (25,) and env.observation_space.contains(obs)
    gait = env.library.nearest(float(obs[0]))
    assert np.allclose(obs[4:], env.bounds.to_normalised(np.append(gait.free, gait.kd)), atol=1e-6)
    action = np.full(21, 0.25, np.float32)
    obs, *_ = env.step(action)
    assert np.allclose(obs[4:], 0.25) and env.observation_space.contains(obs)


def test_a_memory_policy_runs_in_the_closed_loop_and_starts_every_walk_afresh():
    """The network widened with zero weights on the memory inputs acts as the paper network
    (a warm start carried over); the policy resets its memory at every walk."""
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.experiment.scenario import Scenario
    from rabbit_policy.runtime.memory import MemoryConfig, SpeedMemory
    from rabbit_policy.runtime.network import HZDPolicyNet, NetworkForward, widen_inputs
    from rabbit_policy.runtime.policies import NetworkPolicy
    from rabbit_policy.runtime.speed_window import Observation

    bounds = RabbitHZDEnv().bounds
    paper = HZDPolicyNet(bounds.low, bounds.high)
    wide = widen_inputs(paper, 25)
    policy = NetworkPolicy(wide, decision_period=20, memory=SpeedMemory(MemoryConfig.for_period(20)))
    observation = Observation(1.0, 0.95, 0.05)
    assert np.allclose(NetworkForward.of(paper)(observation), NetworkForward.of(wide)(policy.memory.inputs(observation.as_tuple())),
                       atol=1e-6)
    first = walk(policy, Scenario.constant(1.0), 2.0)
    integral = policy.memory.integral
    second = walk(policy, Scenario.constant(1.0), 2.0)
    assert policy.memory.integral == integral  # the same walk again: reset, not carried over
    assert np.array_equal(first.hip_x, second.hip_x)


def test_a_reset_whose_drawn_model_stalls_on_the_first_step_draws_again_and_starts_walking():
    """Seed 1092 of the robust distribution (500 steps, every 20 ticks) first draws friction
    0.4 and a lighter torso at 0.716 m/s: the starting gait stalls before its first touchdown
    (SB3's PPO met it after 43,667 env steps and the reset raised). The reset draws the
    model again; the episode starts at a touchdown, seeded, on the same command."""
    env = RabbitHZDEnv(max_steps=500, decision_period=20, distribution="robust")
    obs, info = env.reset(seed=1092)
    assert not env.loop.failed and len(env.loop.touchdowns) == 1
    assert info["desired_speed"] == pytest.approx(0.716, abs=1e-3)
    again = RabbitHZDEnv(max_steps=500, decision_period=20, distribution="robust")
    assert np.array_equal(again.reset(seed=1092)[0], obs) and again.loop.scenario == env.loop.scenario


def test_the_survival_term_pays_every_step_survived_and_is_checked():
    env = RabbitHZDEnv(max_steps=60, decision_period=20, alive_bonus=0.25)
    env.reset(seed=1)
    _obs, reward, terminated, _tr, info = env.step(np.zeros(21, np.float32))
    assert not terminated and info["reward_alive"] == 0.25
    assert reward == info["reward_tracking"] + info["reward_fall"] + info["reward_alive"] + info["reward_slow"]
    with pytest.raises(ValueError, match="alive_bonus"):
        RabbitHZDEnv(alive_bonus=-1.0)


def test_the_slow_hip_term_pays_below_its_speed_only_and_is_checked():
    """``slow_penalty`` pays per m/s the hip velocity is below SLOW_HIP_SPEED at the end of an
    env step: nothing while walking, a cost that grows as the hip slows (here made to roll
    backward at once)."""
    from rabbit_policy.learning.env import SLOW_HIP_SPEED

    env = RabbitHZDEnv(max_steps=60, decision_period=20, slow_penalty=-2.0)
    env.reset(seed=1, options={"desired_speed": 1.0})
    _obs, reward, _te, _tr, info = env.step(np.zeros(21, np.float32))
    assert info["reward_slow"] == 0.0
    env.loop.data.qvel[0] = -0.6  # m/s: the hip rolling back
    _obs, reward, _te, _tr, info = env.step(np.zeros(21, np.float32))
    hip = float(env.loop.data.qvel[0])
    assert hip < SLOW_HIP_SPEED
    assert info["reward_slow"] == -2.0 * (SLOW_HIP_SPEED - hip) < 0.0
    assert reward == info["reward_tracking"] + info["reward_fall"] + info["reward_alive"] + info["reward_slow"]
    with pytest.raises(ValueError, match="slow_penalty"):
        RabbitHZDEnv(slow_penalty=0.5)


def test_one_episode_length_from_either_spelling():
    """Gymnasium gives ``max_episode_steps`` to its TimeLimit only; the registered
    EpisodeLength wrapper makes the env's own length (which places the command change) the
    same, and ``max_steps`` alone sets the TimeLimit's."""
    for kwargs, steps in (({"max_episode_steps": 5}, 5), ({"max_steps": 7}, 7), ({}, 1500)):
        env = gym.make("RabbitHZD-v0", decision_period=20, **kwargs)
        assert env.unwrapped.max_steps == env.spec.max_episode_steps == steps, kwargs
        if steps == 1500:  # the id's 60 walking steps as 30 s of 20 ms decisions, not 1.2 s (issue 73)
            assert gym.make("RabbitHZD-v0").spec.max_episode_steps == 60
            continue
        env.reset(seed=0)
        ends = [env.step(np.zeros(21, np.float32))[3] for _ in range(steps)]
        assert ends == [False] * (steps - 1) + [True], kwargs
    both = gym.make("RabbitHZD-v0", max_steps=4, max_episode_steps=6)
    assert (both.unwrapped.max_steps, both.spec.max_episode_steps) == (4, 6)  # both given: as given


def test_the_registered_presets_are_the_runs_we_ship_and_train():
    """``RabbitHZD-Shipped-v0`` and ``RabbitHZD-Recovery-v0``: the episodes of the shipped
    policy's preset and the recovery residual's, read from the YAML files themselves, and of
    the shipped checkpoint's stored configuration."""
    import yaml

    from rabbit_policy.learning.env import PRESETS, EpisodeConfig
    from checkpoints import SHIPPED_BEFORE
    from rabbit_policy.runtime.network import PolicyCheckpoint

    root = Path(__file__).resolve().parents[2] / "config" / "train"
    fields = set(EpisodeConfig.__dataclass_fields__) - {"seed"}
    for name, preset_file in (("shipped", "shipped_es.yaml"), ("recovery", "recovery_residual_es.yaml")):
        values = yaml.safe_load((root / preset_file).read_text())
        expected = EpisodeConfig(**{k: v for k, v in values.items() if k in fields})
        assert PRESETS[name] == expected, name
    stored = PolicyCheckpoint.load(SHIPPED_BEFORE).info["config"]
    assert PRESETS["shipped"] == EpisodeConfig(**{k: v for k, v in stored.items() if k in fields})
    for env_id, name in (("RabbitHZD-Shipped-v0", "shipped"), ("RabbitHZD-Recovery-v0", "recovery")):
        env = gym.make(env_id)
        assert env.spec.max_episode_steps == env.unwrapped.max_steps == 500
        unwrapped = env.unwrapped
        assert (unwrapped.features, unwrapped.action, unwrapped.decision_period) == (
            PRESETS[name].features, PRESETS[name].action, PRESETS[name].decision_period)
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
    assert gym.make("RabbitHZD-Recovery-v0").unwrapped.rules.roll_back_after == 0.6


def test_the_integral_band_clip_and_windup_decay_reach_the_env_memory_and_bad_ones_are_refused():
    """``integral_band``/``integral_clip``/``integral_windup_decay`` (train.py
    --integral-band/--integral-clip/--integral-windup-decay): the env's memory integrates as
    the shipped copy with that rule would (``MemoryConfig``, the shipped policy's windup decay
    among them), so a run trains on what ship_policy ships; a negative or non-finite value, or
    one without the integral (the paper's features), is refused in one line."""
    from rabbit_policy.learning.es import ESConfig
    from rabbit_policy.spec.make import make_policy
    from rabbit_policy.runtime.speed_integral import WindupDecay

    config = ESConfig(max_steps=5, decision_period=20, features="memory", action="residual", integral_gain=0.2,
                      integral_band=0.1, integral_clip=0.05, integral_windup_decay=5.0)
    memory = RabbitHZDEnv(**config.env_kwargs()).memory.config
    assert (memory.integral.band, memory.integral.clip, memory.integral.gain, memory.integral.windup_decay) == (
        0.1, 0.05, 0.2, WindupDecay(5.0))
    assert config.memory_config(GaitLibrary.load().speed_range) == memory
    off = RabbitHZDEnv(**replace(config, integral_band=0.0, integral_clip=0.0,
                                 integral_windup_decay=0.0).env_kwargs()).memory.config
    assert (off.integral.band, off.integral.clip, off.integral.windup_decay) == (None, None, None)
    # what a run with the shipped preset and the decay trains on; the feed-forward is a table measured on the trained
    # network (ship_policy --integral-feedforward), and the decay at a walk's start goes with its start
    # (--integral-windup-at-start), as does its opening by a push (the spec's windup_decay.disturbance): all three are
    # set on the shipped copy, not part of this env's training
    shipped = make_policy("learned").memory.config
    shipped = shipped.with_integral(feedforward=None, windup_decay=replace(shipped.integral.windup_decay, at_start=False,
                                                                           disturbance=None))
    assert RabbitHZDEnv(**replace(config, integral_band=0.0, integral_clip=0.0).env_kwargs()).memory.config == shipped
    for bad, message in (({"integral_band": -0.1}, "integral_band must be a finite number >= 0"),
                         ({"integral_clip": float("nan")}, "integral_clip must be a finite number >= 0"),
                         ({"integral_windup_decay": -1.0}, r"integral_windup_decay must be a finite number >= 0 \(s"),
                         ({"integral_band": 0.0, "integral_clip": 0.0, "features": "paper", "action": "direct",
                           "integral_gain": 0.0}, "integral_windup_decay acts on the speed integral"),
                         ({"integral_band": 0.1, "features": "paper", "action": "direct", "integral_gain": 0.0},
                          "integral_band acts on the speed integral")):
        with pytest.raises(ValueError, match=message):
            replace(config, **bad)


def test_the_evaluation_reward_pays_the_walks_graded_reach_and_settling_at_its_end_and_a_fall_is_below_any_walk():
    """reward="evaluation": every step pays 0 until the episode is truncated, then the walk's
    own tracking scores (WalkResult.tracking_scores, the evaluation's reach and settle rules);
    a fall returns exactly fall_penalty."""
    env = RabbitHZDEnv(max_steps=150, decision_period=20, distribution="changes", reward="evaluation",
                       fall_penalty=-1.0)
    env.reset(seed=3, options={"desired_speed": 0.8, "next_speed": 1.2})
    rewards = []
    while True:
        _obs, reward, terminated, truncated, info = env.step(np.zeros(21, np.float32))
        rewards.append(reward)
        if terminated or truncated:
            break
    assert truncated and not terminated and set(rewards[:-1]) == {0.0}
    reach, settle = env.loop.result().tracking_scores()
    assert (info["reward_reach"], info["reward_settle"]) == (reach, settle) and rewards[-1] == reach + settle
    assert "reward_tracking" not in info and settle > 0.0
    falling = RabbitHZDEnv(max_steps=150, decision_period=20, distribution="changes", reward="evaluation",
                           fall_penalty=-1.0)
    falling.reset(seed=3)
    total = 0.0
    for _ in range(150):  # the lowest coefficients and Kd everywhere: RABBIT collapses
        _obs, reward, terminated, _tr, info = falling.step(-np.ones(21, np.float32))
        total += reward
        if terminated:
            break
    assert terminated and total == -1.0 and info["reward_reach"] == info["reward_settle"] == 0.0
    with pytest.raises(ValueError, match="fall_penalty < 0"):
        RabbitHZDEnv(reward="evaluation", fall_penalty=0.0)
    with pytest.raises(ValueError, match="reward must be one of"):
        RabbitHZDEnv(reward="speed")


def test_rgb_array_on_a_headless_machine_picks_an_offscreen_backend_itself():
    """No display and no MUJOCO_GL: importing the package picks EGL (or OSMesa) before mujoco
    is imported, so ``render_mode="rgb_array"`` renders without GLFW's warnings; with neither
    library the render is one clear error."""
    import ctypes.util
    import subprocess
    import sys

    code = ("import gymnasium as gym, rabbit_policy\n"
            "env = gym.make('RabbitHZD-v0', render_mode='rgb_array'); env.reset(seed=0)\n"
            "try:\n    print(env.render().shape)\n"
            "except Exception as exc:\n    print(type(exc).__name__, exc)\n"
            "env.close()\n")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL",
                                                              "PYOPENGL_PLATFORM")}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 0 and "GLFW" not in run.stderr and "Traceback" not in run.stderr, run.stderr
    if ctypes.util.find_library("EGL") or ctypes.util.find_library("OSMesa"):
        assert run.stdout.strip() == "(240, 320, 3)"
    else:
        assert run.stdout.startswith("RenderingUnavailable")
