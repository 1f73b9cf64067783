"""sim_node's stepping rules without ROS (rabbit_sim.stepping): lockstep replies (stamps,
pairing by key or by first answer), resets and pauses, resends, paced and realtime pacing, the watchdog,
lateness, the recorder gate and the statistics."""

from __future__ import annotations

import json
import math
import re

import pytest

from rabbit_msgs_py.pairing import PairingKey, new_key
from rabbit_sim.stepping import (
    Admit, ControllerPairing, LatenessMonitor, Lockstep, Pacer, RealtimeClock, RecorderGate, Reply, TickStatistics,
    Watchdog, WatchdogEvent)

from fake_clock import FakeClock

pytestmark = pytest.mark.unit


A, B = "hzd_controller_node/aaaa", "hzd_controller_node/bbbb"  # two controller instances
T = [1.0] * 4


def test_lockstep_applies_exactly_one_reply_per_state_and_only_to_that_state():
    lock = Lockstep(0.2, clock=FakeClock())
    assert not lock.answers_due(0)  # nothing was due
    lock.published(5_000_000)
    assert not lock.answers_due(4_000_000)  # answers an earlier state
    assert not lock.answers_due(0)  # a made-up stamp
    assert lock.answers_due(5_000_000)
    assert lock.on_reply(T, hold=False) is Reply.STEP
    assert not lock.answers_due(5_000_000)  # a duplicate


def test_a_reset_requested_while_a_reply_is_due_waits_for_it():
    lock = Lockstep(0.2, clock=FakeClock())
    assert lock.request_reset() is False  # nothing due: reset now
    lock.published(7)
    assert lock.request_reset() is True
    assert lock.on_reply([0.0] * 4, hold=False) is Reply.RESET
    assert not lock.awaiting_reply and not lock.reset_requested


def test_a_reply_while_the_step_may_not_run_is_held_until_it_may():
    lock = Lockstep(0.2, clock=FakeClock())
    lock.published(1)
    assert lock.on_reply([3.0] * 4, hold=True) is Reply.HOLD
    assert lock.take_held() == [3.0] * 4
    assert lock.take_held() is None
    lock.published(2)
    lock.restart()  # a reset drops what was due and held
    assert not lock.awaiting_reply and lock.held_torques is None


def test_an_overdue_reply_makes_the_state_go_out_again():
    clock = FakeClock()
    lock = Lockstep(0.2, clock=clock)
    assert lock.resend_due(paused=False) is None  # nothing due
    lock.published(1)
    clock.now += 0.1
    assert lock.resend_due(paused=False) is None
    clock.now += 0.15
    assert lock.resend_due(paused=True) is None  # paused: nothing is overdue
    assert lock.resend_due(paused=False) == pytest.approx(0.25)
    assert lock.resends == 1


def test_without_a_key_the_first_controller_is_paired_until_released_never_by_silence():
    pairing = ControllerPairing()
    assert pairing.admit(A, 1, T) == (Admit.PAIR, A)
    assert pairing.admit(B, 2, [37.0] * 4) == (Admit.REFUSE, B)  # a second controller, the right stamp or not
    assert pairing.admit(A, 2, T) == (Admit.ACCEPT, A)
    for stamp in range(3, 10_000):  # A silent for ever: B is never paired by that
        assert pairing.admit(B, stamp, T)[0] is Admit.REFUSE
    assert pairing.release() == (True, f"released controller {A}: the next controller to answer is paired")
    assert pairing.admit(B, 10_000, T) == (Admit.PAIR, B)
    assert pairing.admit(A, 10_001, T) == (Admit.REFUSE, A)


def test_with_a_key_only_signed_replies_are_applied_and_a_new_signed_instance_is_paired_at_once():
    key = PairingKey.parse(new_key())
    pairing = ControllerPairing(key)
    assert pairing.admit(A, 1, T) == (Admit.REFUSE, A)  # unsigned
    assert pairing.admit(key.sign(A, 1, T), 1, T) == (Admit.PAIR, A)
    assert pairing.admit(key.sign(A, 2, T), 2, T) == (Admit.ACCEPT, A)
    seen = key.sign(A, 2, T)  # a rogue that copies a real reply's frame_id...
    assert pairing.admit(seen, 3, T)[0] is Admit.REFUSE  # ...for another stamp
    assert pairing.admit(seen, 2, [37.0] * 4)[0] is Admit.REFUSE  # ...or other torques
    other = PairingKey.parse(new_key())  # another stack's controller
    assert pairing.admit(other.sign(B, 3, T), 3, T) == (Admit.REFUSE, B)
    assert pairing.admit(A + "#" + "0" * 16, 3, T)[0] is Admit.REFUSE  # a made-up tag
    assert pairing.admit(key.sign(B, 3, T), 3, T) == (Admit.PAIR, B)  # the stack restarted it with the key
    assert pairing.admit(key.sign(A, 4, T), 4, T) == (Admit.PAIR, A)  # (the old one, still signing: logged again)
    assert pairing.release()[0] is False  # with a key: nothing to release


def test_a_pairing_key_is_checked_where_it_enters():
    assert PairingKey.parse("") is None
    with pytest.raises(ValueError, match="16 to 64 characters"):
        PairingKey.parse("short")
    with pytest.raises(ValueError, match="16 to 64 characters"):
        PairingKey.parse("x" * 65)
    assert re.fullmatch(r"pair-[0-9a-f]{32}", new_key()) and new_key() != new_key()


def test_pacer_holds_states_to_the_wall_clock_and_runs_slower_when_behind():
    clock = FakeClock()
    pacer = Pacer(rtf=1.0, slack=0.05, window=5.0, clock=clock)
    pacer.begin(0.0)
    assert pacer.wait(0.001) == pytest.approx(0.001)  # too early: wait 1 ms
    clock.now += 0.001
    assert pacer.wait(0.001) == pytest.approx(0.0)
    clock.now += 0.5  # the machine stalled: 0.5 s behind
    assert pacer.wait(0.002) == 0.0 and pacer.behind_count == 1  # no race to catch up: re-anchored
    assert pacer.wait(0.003) == pytest.approx(0.001)  # paced from the new anchor
    assert Pacer(rtf=2.0, clock=clock).wait(0.0) == 0.0
    half = Pacer(rtf=0.5, clock=clock)
    half.begin(0.0)
    assert half.wait(0.01) == pytest.approx(0.02)  # rtf 0.5: 10 ms of sim time per 20 ms
    with pytest.raises(ValueError, match="rtf"):
        Pacer(rtf=0.0)


def test_pacer_reports_the_achieved_real_time_factor_once_per_window():
    clock = FakeClock()
    pacer = Pacer(rtf=1.0, window=5.0, clock=clock)
    pacer.begin(0.0)
    clock.now += 4.0
    assert pacer.achieved(2.0) is None
    clock.now += 1.0
    assert pacer.achieved(2.5) == pytest.approx(0.5)


def test_lateness_monitor_warns_then_stops_a_loop_that_fell_too_far_behind():
    clock = FakeClock()
    monitor = LatenessMonitor(max_late_fraction=0.5, clock=clock)
    stats = TickStatistics()
    stats.ticks, stats.late_ticks = 1000, 10
    clock.now += 1.0
    assert monitor.check(stats, skipped=0) is None  # 1 % late: on time
    stats.ticks, stats.late_ticks = 2000, 210
    clock.now += 1.0
    late = monitor.check(stats, skipped=0)
    assert late is not None and late.late == 200 and not late.stop
    stats.ticks, stats.late_ticks = 3000, 900
    assert monitor.check(stats, skipped=0) is None  # not a second yet
    clock.now += 1.0
    late = monitor.check(stats, skipped=3)
    assert late.stop and late.fraction == pytest.approx(0.69) and late.skipped == 3


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


def test_statistics_count_late_ticks_and_exact_latencies_by_stamp_and_stay_json():
    stats = TickStatistics()
    assert json.loads(json.dumps(stats.summary(0.0), allow_nan=False))["late_fraction"] is None
    stats.state_sent(1.000, 0, track_latency=True)
    stats.tick(1.000)
    stats.torque_received(1.0005, 0)
    stats.state_sent(1.001, 1_000_000, track_latency=True)
    stats.realtime_tick_due(1.002)  # the reply to the state at 1.001 has not come: late
    stats.tick(1.002)
    summary = stats.summary(0.002)
    assert summary["late_ticks"] == 1 and summary["late_fraction"] == pytest.approx(0.5)
    assert summary["latency_p50_ms"] == pytest.approx(0.5)
    stats.state_sent(1.002, 2_000_000, track_latency=True)
    stats.torque_received(1.0025, 2_000_000)  # the newest answered first: its own latency, not FIFO
    assert stats.latencies_ms[-1] == pytest.approx(0.5) and not stats.awaiting_reply
    stats.torque_received(1.003, 1_000_000)  # the late one, 2 ms after its state
    assert stats.latencies_ms[-1] == pytest.approx(2.0)
    stats.state_sent(1.003, 3_000_000, track_latency=True)
    stats.realtime_tick_due(1.1)  # unanswered for 97 ms: lost, dropped from the wait
    assert not stats.sent and not stats.awaiting_reply


def test_recorder_gate_holds_the_start_and_any_lag_beyond_its_limit_by_stamps():
    ms = 1_000_000
    assert not RecorderGate(False).holds(100 * ms)
    gate = RecorderGate(True, max_lag=4, timestep_ns=ms)
    assert not gate.holds(None)  # nothing published: nothing to wait for
    assert gate.holds(0)  # the recorder has no state yet
    gate.recorded = 0
    assert not gate.holds(0) and not gate.holds(4 * ms) and gate.holds(5 * ms)
    gate.recorded = 3 * ms  # the newest report is all that counts: a lost one is harmless
    assert not gate.holds(7 * ms)
    assert gate.holds(0)  # a reset: the report from before it holds until t = 0 is recorded
    assert "t = 0.003 s" in gate.behind(7 * ms)


def test_sim_settings_are_checked_without_ros():
    """sim_node's settings are a ROS-free dataclass: bad values are one-line ValueErrors
    (the node turns them into its start-up error)."""
    from rabbit_sim.stepping.settings import SimSettings

    assert SimSettings().mode == "lockstep"
    for bad, message in (({"mode": "fast"}, "mode must be one of"), ({"rtf": 0.0}, "rtf must be"),
                         ({"push_schedule": "1:5e6:0.1"}, "within"), ({"max_late_fraction": 2.0}, "(0, 1]"),
                         ({"friction": -0.1}, "friction must be"), ({"torso_mass_scale": 0.0}, "torso_mass_scale"),
                         ({"torque_delay": 0.0015}, "whole number of ms"), ({"torque_delay": math.nan}, "torque_delay")):
        with pytest.raises(ValueError, match=re.escape(message)):
            SimSettings(**bad)
    settings = SimSettings(friction=0.4, torso_mass_scale=1.2, torque_delay=0.003)
    assert settings.model_options.friction == 0.4 and settings.delay_ticks == 3
    assert SimSettings().model_options.friction is None  # 0: the model's own
