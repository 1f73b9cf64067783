"""The training episodes' distributions (``rabbit_policy.learning.env.DISTRIBUTIONS``): what
each draws (commands, pushes, models, delays, noise) over seeded resets."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rabbit_policy.learning.env import DISTRIBUTIONS, RabbitHZDEnv

pytestmark = pytest.mark.sim


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


def test_push_episodes_push_every_episode_between_the_least_and_the_largest_impulse_both_ways():
    env = RabbitHZDEnv(max_steps=250, decision_period=20, distribution="pushes")
    impulses = []
    for seed in range(16):
        env.reset(seed=seed)
        (push,) = env.loop.scenario.pushes
        assert 1.0 - 1e-9 <= push.time <= 4.0 + 1e-9  # inside the 5 s episode, 1 s from either end
        impulses.append(push.impulse)
    assert all(6.0 - 1e-9 <= abs(i) <= 20.0 + 1e-9 for i in impulses)
    assert min(impulses) < 0.0 < max(impulses)


def test_robust_episodes_add_noise_to_the_measured_inputs_only_and_reward_the_true_speed():
    noisy = RabbitHZDEnv(max_steps=500, decision_period=20, distribution="robust")
    clean = RabbitHZDEnv(max_steps=500, decision_period=20,
                         distribution=replace(DISTRIBUTIONS["robust"], observation_noise=0.0))
    obs_noisy, _ = noisy.reset(seed=5)
    obs_clean, _ = clean.reset(seed=5)
    assert obs_noisy[0] == obs_clean[0]  # the command is not measured: no noise
    assert not np.allclose(obs_noisy[1:], obs_clean[1:])
    action = np.zeros(21, np.float32)
    for _ in range(3):
        _, reward_noisy, _, _, info_noisy = noisy.step(action)
        _, reward_clean, _, _, info_clean = clean.step(action)
        assert reward_noisy == reward_clean and info_noisy["mean_speed"] == info_clean["mean_speed"]


def _one_phase_push_each(distribution: str, seeds: int = 24) -> list[tuple]:
    """Each of ``seeds`` episodes of 500 decisions: its scenario (one phase push, no timed one),
    its push, the push's direction (+1 forward) and its impulse over classic's margin at the
    command in force."""
    from rabbit_policy.evaluation.push_recovery import classic_margin

    env = RabbitHZDEnv(max_steps=500, decision_period=20, distribution=distribution)
    episodes = []
    for seed in range(seeds):
        env.reset(seed=seed)
        scenario = env.loop.scenario
        assert scenario.pushes == () and len(scenario.phase_pushes) == 1
        (push,) = scenario.phase_pushes
        command = next(v for t, v in reversed(scenario.schedule) if t <= push.after)
        direction = 1 if push.impulse > 0 else -1
        episodes.append((scenario, push, direction, abs(push.impulse) / classic_margin(command, direction)))
    return episodes


def test_recovery_episodes_push_at_a_phase_of_a_step_around_classics_margin_mostly_backward():
    directions = []
    for _scenario, push, direction, ratio in _one_phase_push_each("recovery"):
        assert 1.0 - 1e-9 <= push.after <= 9.0 + 1e-9 and 0.0 <= push.phase < 1.0
        assert 0.8 - 1e-9 <= ratio <= 2.2 + 1e-9
        directions.append(direction)
    assert 12 <= directions.count(-1) < 24 and directions.count(1) >= 1


def _margin_pushes(distribution: str, seeds: int) -> list[int]:
    """The directions (+1 forward) of the pushes in ``seeds`` episodes of ``distribution``,
    each checked to be at a phase, 0.5-1.5x classic's margin at the command in force, on the
    nominal model with changing commands."""
    from rabbit_policy.evaluation.push_recovery import classic_margin

    env = RabbitHZDEnv(max_steps=500, decision_period=20, distribution=distribution)
    directions = []
    for seed in range(seeds):
        env.reset(seed=seed)
        scenario = env.loop.scenario
        assert scenario.pushes == () and scenario.model == env.model_options and len(scenario.schedule) >= 2
        for push in scenario.phase_pushes:
            command = next(v for t, v in reversed(scenario.schedule) if t <= push.after)
            direction = 1 if push.impulse > 0 else -1
            assert 0.5 - 1e-9 <= abs(push.impulse) / classic_margin(command, direction) <= 1.5 + 1e-9
            directions.append(direction)
    return directions


def test_changes_episodes_push_half_of_them_at_a_phase_around_classics_margin_on_the_nominal_model():
    assert 6 <= len(_margin_pushes("changes", 24)) <= 18


def test_forward_episodes_push_three_in_four_two_thirds_of_them_forward_around_classics_margin():
    directions = _margin_pushes("forward", 48)
    assert 28 <= len(directions) <= 44  # 36 expected of 48
    assert directions.count(1) >= 1.4 * directions.count(-1)  # two to one expected


def test_decided_episodes_push_every_one_where_the_screen_decides_forward_and_backward_alike():
    directions = []
    for scenario, _push, direction, ratio in _one_phase_push_each("decided"):
        assert len(scenario.schedule) >= 2
        low, high = (0.8, 1.6) if direction > 0 else (1.2, 2.4)
        assert low - 1e-9 <= ratio <= high + 1e-9
        directions.append(direction)
    assert 6 <= directions.count(1) <= 18
    with pytest.raises(ValueError, match="backward_scale must be > 0"):
        replace(DISTRIBUTIONS["decided"], backward_scale=0.0)


def test_forward_guard_episodes_push_every_one_forward_at_a_phase_near_classics_margin():
    for scenario, push, direction, ratio in _one_phase_push_each("forward_guard"):
        assert direction == 1 and 0.9 - 1e-9 <= ratio <= 1.4 + 1e-9
        assert 0.0 <= push.phase < 1.0 and len(scenario.schedule) >= 2


def test_the_screen_guard_walks_steady_at_the_screens_speeds_pushed_forward_near_classics_margin():
    """guard_set "screen": each episode one of the screen's push speeds, held (no change), one
    forward push at a phase at 1.0-1.3x classic's margin, the nominal model without a delay."""
    from rabbit_policy.evaluation.push_recovery import classic_margin
    from rabbit_policy.evaluation.shipping import ScreenTrials
    from rabbit_policy.learning.es import guard_episodes

    episodes = guard_episodes(np.random.default_rng(0), 10, "screen")
    assert [first for _seed, first, _second in episodes] == list(ScreenTrials().speeds) * 2
    env = RabbitHZDEnv(max_steps=500, decision_period=20, distribution="screen_forward")
    for seed, first, second in episodes:
        env.reset(seed=seed, options={"desired_speed": first, "next_speed": second})
        scenario = env.loop.scenario
        assert {v for _t, v in scenario.schedule} == {first} and scenario.torque_delay == 0.0
        (push,) = scenario.phase_pushes
        assert push.impulse > 0 and 1.0 - 1e-9 <= push.impulse / classic_margin(first, 1) <= 1.3 + 1e-9
    assert guard_episodes(np.random.default_rng(0), 10, "changes") != episodes
