"""sim_node's stepping rules without ROS (rabbit_sim.stepping): lockstep replies, resets and
pauses, resends, realtime pacing, the watchdog and the statistics."""

from __future__ import annotations

import json

import pytest

from rabbit_sim.stepping import Lockstep, RealtimeClock, Reply, TickStatistics, Watchdog, WatchdogEvent

pytestmark = pytest.mark.unit


class FakeClock:
    """A settable wall clock (s) for rules that read the time."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_lockstep_applies_exactly_one_reply_per_state():
    lock = Lockstep(0.2, FakeClock())
    assert lock.on_reply([1.0] * 4, paused=False) is Reply.IGNORE  # nothing was due
    lock.published()
    assert lock.on_reply([1.0] * 4, paused=False) is Reply.STEP
    assert lock.on_reply([2.0] * 4, paused=False) is Reply.IGNORE  # a duplicate / second controller


def test_a_reset_requested_while_a_reply_is_due_waits_for_it():
    lock = Lockstep(0.2, FakeClock())
    assert lock.request_reset() is False  # nothing due: reset now
    lock.published()
    assert lock.request_reset() is True
    assert lock.on_reply([0.0] * 4, paused=False) is Reply.RESET
    assert not lock.awaiting_reply and not lock.reset_requested


def test_a_reply_while_paused_is_held_until_the_simulation_runs():
    lock = Lockstep(0.2, FakeClock())
    lock.published()
    assert lock.on_reply([3.0] * 4, paused=True) is Reply.HOLD
    assert lock.take_held() == [3.0] * 4
    assert lock.take_held() is None
    lock.published()
    lock.restart()  # a reset drops what was due and held
    assert not lock.awaiting_reply and lock.held_torques is None


def test_an_overdue_reply_makes_the_state_go_out_again():
    clock = FakeClock()
    lock = Lockstep(0.2, clock)
    assert lock.resend_due(paused=False) is None  # nothing due
    lock.published()
    clock.now += 0.1
    assert lock.resend_due(paused=False) is None
    clock.now += 0.15
    assert lock.resend_due(paused=True) is None  # paused: nothing is overdue
    assert lock.resend_due(paused=False) == pytest.approx(0.25)
    assert lock.resends == 1


def test_realtime_clock_runs_due_ticks_catches_up_a_little_and_skips_the_rest():
    clock = FakeClock()
    pacer = RealtimeClock(0.001, max_burst=2, clock=clock)
    assert pacer.due() == 1  # the first tick is due at once
    assert pacer.due() == 0 and pacer.wait_time() == pytest.approx(0.001)
    clock.now += 0.0021  # woken late: two ticks due, run back to back
    assert pacer.due() == 2 and pacer.skipped == 0
    clock.now += 0.05  # a 50 ms stall: one tick now, the other 49 skipped, no burst
    assert pacer.due() == 1 and pacer.skipped == 49
    assert pacer.due() == 0
    pacer.restart()
    assert pacer.wait_time() == pytest.approx(0.001)


def test_watchdog_damps_stale_torques_and_says_when():
    dog = Watchdog(timeout=0.05, damping=20.0)
    torques, event = dog.torques([1.0] * 4, latest_wall=-1.0, now=10.0, joint_rates=[0.5, -1.0, 0.0, 2.0])
    assert torques == [-10.0, 20.0, -0.0, -40.0] and event is WatchdogEvent.TRIPPED
    _, event = dog.torques([1.0] * 4, latest_wall=9.0, now=10.0, joint_rates=[0.0] * 4)
    assert event is None and dog.damped_ticks == 2
    torques, event = dog.torques([1.0] * 4, latest_wall=9.99, now=10.0, joint_rates=[0.0] * 4)
    assert torques == [1.0] * 4 and event is WatchdogEvent.RESUMED and not dog.active


def test_statistics_count_late_ticks_and_latencies_and_stay_json():
    stats = TickStatistics()
    assert json.loads(json.dumps(stats.summary(0.0), allow_nan=False))["late_fraction"] is None
    stats.state_sent(1.000, track_latency=True)
    stats.tick(1.000)
    stats.torque_received(1.0005)
    stats.state_sent(1.001, track_latency=True)
    stats.realtime_tick_due(1.002)  # the reply to the state at 1.001 has not come: late
    stats.tick(1.002)
    summary = stats.summary(0.002)
    assert summary["late_ticks"] == 1 and summary["late_fraction"] == pytest.approx(0.5)
    assert summary["latency_p50_ms"] == pytest.approx(0.5)
    stats.realtime_tick_due(1.1)  # unanswered for 99 ms: lost, dropped
    assert not stats.unanswered


def test_recorder_gate_holds_the_start_and_any_lag_beyond_its_limit():
    from rabbit_sim.stepping import RecorderGate

    off = RecorderGate(False)
    assert not off.missed_start() and not off.lags(100)
    gate = RecorderGate(True, max_lag=4)
    assert gate.missed_start()
    gate.recorded = 1
    assert not gate.missed_start() and not gate.lags(5) and gate.lags(6)


def test_source_probe_counts_replies_for_its_window():
    from rabbit_sim.stepping import SourceProbe, Verdict

    clock = FakeClock()
    probe = SourceProbe(window=0.3, clock=clock)
    probe.start()
    probe.reply([1.0] * 4)
    assert probe.verdict() is None  # the window is not over
    clock.now += 0.31
    assert probe.verdict() is Verdict.ONE and not probe.active and probe.torques == [1.0] * 4
    probe.start()
    probe.reply([1.0] * 4)
    probe.reply([2.0] * 4)
    clock.now += 0.31
    assert probe.verdict() is Verdict.MANY and probe.active  # two live sources: go on probing
    probe.start()
    clock.now += 0.31
    assert probe.verdict() is Verdict.NONE
