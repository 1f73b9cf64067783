"""PPO's push-recovery parts (issue 37 item 3): the environment's privileged state, the
critic's running normalisation, the return scale, and one iteration with all of them on."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from rabbit_policy.learning.env import PRIVILEGED_STATE, RabbitHZDEnv
from rabbit_policy.learning.ppo import PPOConfig, PPOTrainer, ReturnScale, RunningMoments
from rabbit_policy.learning.warm_start import zero_residual_network


@pytest.mark.unit
def test_running_moments_equal_the_moments_of_everything_folded_in():
    rng = np.random.default_rng(0)
    data = rng.normal([1.0, -5.0, 100.0], [0.1, 2.0, 30.0], (300, 3))
    moments = RunningMoments(3)
    for chunk in np.array_split(data, 7):
        moments.update(torch.as_tensor(chunk))
    assert np.allclose(moments.mean.numpy(), data.mean(0), rtol=0, atol=1e-6 * np.abs(data).max())
    assert np.allclose(moments.var.numpy(), data.var(0), rtol=1e-4)
    z = moments.normalise(torch.as_tensor(data, dtype=torch.float32)).numpy()
    assert np.allclose(z.mean(0), 0.0, atol=1e-3) and np.allclose(z.std(0), 1.0, atol=1e-3)


@pytest.mark.unit
def test_the_return_scale_divides_by_the_discounted_returns_std_and_restarts_them_at_an_episode_end():
    scale = ReturnScale(envs=2, gamma=0.5)
    scale(np.array([1.0, 2.0]), np.array([False, True]))
    assert np.array_equal(scale.returns, [1.0, 0.0])  # the second environment's episode ended
    out = scale(np.array([1.0, 4.0]), np.array([False, False]))
    returns = np.array([[1.0], [2.0], [1.5], [4.0]])  # every return folded in so far
    assert np.isclose(out[1] / 4.0, 1.0 / np.sqrt(returns.var() + 1e-8), rtol=1e-3)
    restored = ReturnScale(envs=2, gamma=0.5)
    restored.load_state_dict(scale.state_dict())
    assert np.array_equal(restored(np.ones(2), np.zeros(2, bool)), scale(np.ones(2), np.zeros(2, bool)))


@pytest.mark.sim
def test_the_privileged_state_names_the_push_the_model_and_the_body():
    env = RabbitHZDEnv(distribution="recovery", decision_period=20, max_steps=300)
    _, info = env.reset(seed=3)
    state = dict(zip(PRIVILEGED_STATE, info["privileged"]))
    assert len(info["privileged"]) == len(PRIVILEGED_STATE)
    impulse = state["push_impulse"]
    assert impulse != 0.0 and state["push_pending"] == 1.0 and state["push_force"] == 0.0
    scenario = env.loop.scenario
    assert state["torso_mass_scale"] == scenario.model.torso_mass_scale
    assert np.isclose(state["torque_delay"], scenario.torque_delay)
    assert np.allclose(list(state.values())[:5], env.loop.body_state(), atol=1e-6)
    forces = []
    for _ in range(300):
        _, _, terminated, truncated, info = env.step(np.zeros(21, np.float32))
        forces.append(dict(zip(PRIVILEGED_STATE, info["privileged"])))
        if terminated or truncated:
            break
    acting = [f["push_force"] for f in forces if f["push_force"] != 0.0]
    assert acting and np.allclose(acting, impulse / 0.1, rtol=1e-5)  # the push, while it acts
    assert forces[-1]["push_pending"] == 0.0


@pytest.mark.sim
def test_one_ppo_iteration_with_a_privileged_critic_scaled_rewards_and_separate_clips():
    config = PPOConfig(envs=2, steps=24, epochs=2, minibatches=2, max_steps=10, decision_period=20,
                       distribution="recovery", features="body", action="residual", residual_base="recovery",
                       privileged_critic=True, normalize_rewards=True, separate_clip=True, seed=1)
    probe = RabbitHZDEnv(**config.env_kwargs())
    net = zero_residual_network(probe.bounds.low, probe.bounds.high, probe.observation_space.shape[0], seed=1)
    trainer = PPOTrainer(net, config)
    try:
        stats = trainer.step()
        assert stats["env_steps"] == 48 and stats["episodes"] >= 2  # 10-step episodes: truncations bootstrapped
        assert np.isfinite(stats["value_loss"]) and np.isfinite(stats["policy_loss"])
        assert trainer.critic.body[0].in_features == probe.observation_space.shape[0] + len(PRIVILEGED_STATE)
        assert float(trainer.critic.moments.count) > 48  # the rollout's critic inputs folded in
        state = trainer.state_dict()
        assert "reward_scale" in state
    finally:
        trainer.close()
