"""ES with ``optimizer: ars`` (issue 72, item 4): the step is ARS V2-t's, lr times the return
differences' directions over the std of the returns, with no Adam to turn a noise gradient into
full steps; recomputed here from the same draws and rollouts."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from rabbit_policy.learning.spec_env import make_env
from rabbit_policy.learning.es import ESConfig, EvolutionStrategy, _evaluate, stratified_episodes
from rabbit_policy.parallel import LocalBackend
from rabbit_policy.runtime.network import HZDPolicyNet

@pytest.mark.sim
def test_an_ars_step_is_lr_times_the_differences_over_the_returns_std():
    config = ESConfig(max_steps=4, distribution="paper", action="residual", pairs=3, episodes=1, sigma=0.2,
                      lr=0.05, weight_decay=0.0, optimizer="ars", top=2, seed=7)
    env = make_env(config.env_kwargs())
    net = HZDPolicyNet(env.bounds.low, env.bounds.high, inputs=env.observation_space.shape[0], output="tanh")
    es = EvolutionStrategy(net, config, LocalBackend(1))
    theta = es.theta.copy()
    rng = np.random.default_rng(7)
    episodes = stratified_episodes(rng, 1, (0.7, 1.5))
    eps = rng.standard_normal((3, theta.size))
    key = es.env_key
    returns = np.array([np.mean([r.total for r in _evaluate((key, m, episodes))])
                        for m in [theta + 0.2 * e for e in eps] + [theta - 0.2 * e for e in eps]])
    es.step()
    es.close()
    plus, minus = returns[:3], returns[3:]
    best = np.argsort(-np.maximum(plus, minus), kind="stable")[:2]
    spread = np.std(np.concatenate([plus[best], minus[best]]))
    expected = theta + 0.05 * ((plus[best] - minus[best]) @ eps[best]) / (2 * spread)
    assert np.allclose(es.theta, expected, rtol=1e-9, atol=1e-12)


@pytest.mark.unit
def test_an_unknown_optimizer_is_refused():
    with pytest.raises(ValueError, match="optimizer must be one of"):
        ESConfig(optimizer="sgd")


def _guarded(slack: int, reference: int | None) -> tuple[EvolutionStrategy, np.ndarray, dict]:
    """A guarded ES's start, and its first step's statistics (``reference``: the start's guard
    falls set by hand, None: measured)."""
    config = ESConfig(max_steps=150, distribution="changes", action="residual", pairs=2, episodes=1, sigma=0.5,
                      lr=0.5, weight_decay=0.0, optimizer="ars", seed=3, guard=2, guard_slack=slack)
    env = make_env(config.env_kwargs())
    torch.manual_seed(0)
    net = HZDPolicyNet(env.bounds.low, env.bounds.high, inputs=env.observation_space.shape[0], output="tanh")
    es = EvolutionStrategy(net, config, LocalBackend(1))
    start = es.theta.copy()
    es.guard_reference = reference
    stats = es.step()
    es.close()
    return es, start, stats


@pytest.mark.sim
def test_the_guard_takes_an_update_within_the_starts_falls_and_refuses_one_beyond():
    free, start, stats = _guarded(slack=2, reference=None)  # 2 episodes: never more than 2 falls beyond
    assert stats["update_taken"] == 1 and not np.array_equal(free.theta, start)
    assert stats["guard_falls"] <= stats["guard_reference"] + 2
    assert free.guard_episodes and all(0.7 <= a <= 1.5 for _seed, a, _b in free.guard_episodes)
    held, start_again, refused = _guarded(slack=0, reference=-1)  # no update can fall fewer than -1 times
    assert np.array_equal(start_again, start)  # the same seed, the same start
    assert refused["update_taken"] == 0 and np.array_equal(held.theta, start)
    assert refused["guard_falls"] == stats["guard_falls"]  # the same update, rolled out on the same guard set


@pytest.mark.unit
def test_a_negative_guard_is_refused():
    with pytest.raises(ValueError, match="guard and guard_slack must be >= 0"):
        ESConfig(guard=-1)
