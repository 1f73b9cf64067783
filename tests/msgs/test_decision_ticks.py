"""The due-state rule of decisions every N ticks (rabbit_msgs_py.decision_ticks), which the
policy's DecisionClock and a decision_sync controller both follow."""

from __future__ import annotations

import pytest

from rabbit_msgs_py.decision_ticks import PeriodicDecisions

pytestmark = pytest.mark.unit


def test_every_nth_tick_is_due_and_the_placed_state_never():
    ticks = PeriodicDecisions(20)
    assert [t for t in range(0, 101) if ticks.due(t)] == [20, 40, 60, 80, 100]


def test_a_state_sent_again_is_due_once_and_a_missed_one_moves_the_next():
    ticks = PeriodicDecisions(20, tick=1000)  # stamps in a finer unit (ns in the nodes)
    assert ticks.due(20_000) and not ticks.due(20_000)  # a re-send
    assert not ticks.due(39_000)
    assert ticks.due(45_000)  # 40 ms missed: decided at the first state past it, once
    assert not ticks.due(59_000) and ticks.due(60_000)


def test_an_older_stamp_or_zero_is_a_new_placement():
    ticks = PeriodicDecisions(20)
    assert ticks.due(20) and ticks.due(40)
    assert not ticks.due(5)  # older: placed again, counted from there
    assert ticks.due(20)
    assert not ticks.due(0) and not ticks.due(19) and ticks.due(20)


def test_joining_mid_run_follows_the_clock_that_started_at_the_placement():
    ticks = PeriodicDecisions(20)
    ticks.join(35)
    assert [t for t in range(36, 81) if ticks.due(t)] == [40, 60, 80]
    ticks.join(40)  # on a due state already seen: the next one is due
    assert not ticks.due(41) and ticks.due(60)


@pytest.mark.parametrize("period, tick", [(0, 1), (-1, 1), (2.5, 1), (20, 0)])
def test_bad_periods_are_refused(period, tick):
    with pytest.raises(ValueError):
        PeriodicDecisions(period, tick)


@pytest.mark.parametrize("bad", [-1, 1.5, True, None, "20"])
def test_a_training_env_and_its_episodes_take_a_timing_in_ticks_through_the_one_check(bad):
    from rabbit_msgs_py.decision_ticks import decision_ticks

    assert decision_ticks(0) == 0 and decision_ticks(20) == 20
    with pytest.raises(ValueError, match="decision timing"):
        decision_ticks(bad)


def test_gait_timing_carries_the_controller_settings_a_policy_needs():
    from rabbit_msgs_py.decision_ticks import gait_timing, parse_gait_timing, timing_settings

    settings = {"within_step_blend": 0.0, "within_step_until": 1.0, "kp": 3000.0,
                "hip_coefficient_range": (-1.6, 1.6)}
    text = gait_timing(20, settings)
    assert text == "at_once:20 within_step_blend=0.0 within_step_until=1.0 kp=3000.0 hip_coefficient_range=-1.6,1.6"
    assert parse_gait_timing(text) == ("at_once", 20) and timing_settings(text) == settings
    assert timing_settings(text + " signed=policy_node/0a1b2c3d:0123456789abcdef") == settings  # the signature aside
    assert gait_timing(0) == "next_step" and timing_settings("next_step") == {}
    for bad in ("at_once:20 gain=1.0", "at_once:20 kp=nan", "at_once:20 blend_phase=x", "at_once:20 kp=inf"):
        with pytest.raises(ValueError, match="a setting is one of"):
            timing_settings(bad)
    for bad in ("at_once:20 kp=1,2", "at_once:20 hip_coefficient_range=1.0"):
        with pytest.raises(ValueError, match="is (one number|a range)"):
            timing_settings(bad)


def test_the_state_before_each_decision_is_the_one_whose_phase_it_reads():
    from rabbit_msgs_py.decision_ticks import precedes_decision

    assert [k for k in range(0, 61) if precedes_decision(k, 20, 1)] == [19, 39, 59]
    assert all(precedes_decision(k * 1_000_000, 0) for k in range(5))  # once per step, or not known: every state
