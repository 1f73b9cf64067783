"""The controller node's rules without ROS (rabbit_hzd_controller.controller_driver.ControllerDriver): events
in, actions out, on real gaits and states with a fake wall clock."""

from __future__ import annotations

import pytest

from rabbit_hzd_controller.controller import ControllerConfig, HZDController, infer_stance
from rabbit_hzd_controller.gait_state import state_on_gait
from rabbit_hzd_controller.controller_driver import Answer, ControllerDriver, Log, Repeat
from rabbit_msgs_py.decision_ticks import parse_gait_timing
from rabbit_policy.runtime.gait_library import GaitLibrary

from fake_clock import FakeClock

pytestmark = pytest.mark.unit

MS = 1_000_000  # ns


@pytest.fixture(scope="module")
def gaits():
    library = GaitLibrary.load()
    slow, fast = (list(library.nearest(v).alpha) for v in (0.8, 1.2))
    q, dq = state_on_gait(library.nearest(1.0).alpha, 1.0)
    return slow, fast, (list(q), list(dq))


def _answers(actions) -> list[int]:
    return [a.stamp for a in actions if isinstance(a, Answer)]


def test_a_state_before_the_gait_waits_and_is_answered_once_it_is_complete(gaits):
    slow, _fast, (q, dq) = gaits
    sync = ControllerDriver(ControllerConfig())
    assert sync.on_state(0, q, dq) == [] and sync.missing == ["alpha", "kd"]
    assert sync.on_gait_part("alpha", slow) == []
    (answer,) = sync.on_gait_part("kd", 50.0)
    assert answer.stamp == 0 and len(answer.torques) == 4 and not answer.touchdown
    expected = HZDController(slow, 50.0, ControllerConfig(), infer_stance(q, ControllerConfig().geometry))
    assert answer.torques == expected.compute(q, dq)  # the ROS-free loop's law, the start gait


def test_decision_sync_holds_a_due_state_until_its_decision_and_applies_it_to_that_state(gaits):
    slow, fast, (q, dq) = gaits
    sync = ControllerDriver(ControllerConfig(), decision_sync=True, clock=FakeClock())
    sync.on_gait_part("alpha", slow)
    sync.on_gait_part("kd", 50.0)
    assert sync.on_state(0, q, dq) == [] and sync.missing == ["gait_timing"]  # a due decision would be missed
    actions = sync.on_gait_timing("at_once", 20)
    assert [type(a) for a in actions] == [Log, Answer] and "blended in over 0.2 of phase" in actions[0].text
    for tick in range(1, 20):
        assert _answers(sync.on_state(tick * MS, q, dq)) == [tick * MS]
    assert sync.on_state(20 * MS, q, dq) == []  # due: held
    assert sync.on_state(20 * MS, q, dq) == []  # sent again while it waits: still held, answered once
    assert sync.on_gait_part("alpha", fast) == []
    (answer,) = sync.on_gait_part("kd", 60.0)
    assert answer.stamp == 20 * MS and sync.decisions_waited == 1
    reference = HZDController(slow, 50.0, ControllerConfig(), sync.controller.stance)
    reference.apply_now(tuple(fast), 60.0)
    assert answer.torques == reference.compute(q, dq)  # the decision applied to that very state


def _holding_a_due_state(alpha, q, dq) -> tuple[FakeClock, ControllerDriver]:
    """A lockstep controller (decision_sync, a 2 s timeout, a fake clock) deciding every 20 ticks
    on ``alpha``, Kd 50, after the states of ticks 0-20: the one of tick 20 is held for its decision."""
    clock = FakeClock()
    sync = ControllerDriver(ControllerConfig(), decision_sync=True, decision_timeout=2.0, clock=clock)
    sync.on_gait_part("alpha", alpha)
    sync.on_gait_part("kd", 50.0)
    sync.on_gait_timing("at_once", 20)
    for tick in range(0, 21):
        sync.on_state(tick * MS, q, dq)
    return clock, sync


def test_a_decision_that_never_comes_is_given_up_and_gaits_then_apply_on_arrival(gaits):
    slow, fast, (q, dq) = gaits
    clock, sync = _holding_a_due_state(slow, q, dq)
    for _ in range(4):  # the lockstep simulator sends the held state again while it waits (resend_timeout)
        clock.now += 0.5
        assert sync.on_state(20 * MS, q, dq) == [] and sync.check_held() == []
    clock.now += 0.5
    warning, answer = sync.check_held()
    assert warning.level == "warning" and "no decision from the policy within 2 s" in warning.text
    assert answer.stamp == 20 * MS and sync.decisions_timed_out == 1 and sync.simulator_silences == 0
    assert sync.on_state(40 * MS, q, dq)[0].stamp == 40 * MS  # not held while paused
    sync.on_gait_part("alpha", fast)
    sync.on_gait_part("kd", 60.0)  # the policy is back: sync resumes
    assert sync.on_state(60 * MS, q, dq) == []


def test_a_rejected_part_counts_as_its_decisions_part(gaits):
    slow, _fast, (q, dq) = gaits
    sync = ControllerDriver(ControllerConfig(), decision_sync=True)
    sync.on_gait_part("alpha", slow)
    sync.on_gait_part("kd", 50.0)
    sync.on_gait_timing("at_once", 20)
    for tick in range(0, 21):
        sync.on_state(tick * MS, q, dq)
    assert sync.on_gait_part("alpha", None) == []  # rejected
    (answer,) = sync.on_gait_part("kd", 70.0)
    assert answer.stamp == 20 * MS and sync.controller.kd == 70.0 and sync.alpha == slow


def test_a_resent_state_gets_the_same_reply_and_a_reset_answers_it_anew(gaits):
    slow, _fast, (q, dq) = gaits
    sync = ControllerDriver(ControllerConfig())
    sync.on_gait_part("alpha", slow)
    sync.on_gait_part("kd", 50.0)
    sync.on_resets(1)  # the count in force at start: nothing to restart
    assert _answers(sync.on_state(0, q, dq)) == [0]
    assert sync.on_state(0, q, dq) == [Repeat(0)] and sync.replies_repeated == 1
    actions = sync.on_resets(2)  # the placed state was taken for a re-send: answered now, restarted
    assert [type(a) for a in actions] == [Log, Answer] and "controller restarted" in actions[0].text
    assert _answers(sync.on_state(5 * MS, q, dq)) == [5 * MS]
    assert _answers(sync.on_state(0, q, dq)) == [0]  # an older stamp: restarted too (no /sim/resets)


def test_a_controller_joining_mid_run_answers_its_first_state_at_once(gaits):
    """The stack restarted the controller: its first state is due for a decision that went
    to the old instance; it is answered at once, the next due one waits as usual."""
    slow, _fast, (q, dq) = gaits
    sync = ControllerDriver(ControllerConfig(), decision_sync=True)
    sync.on_resets(1)
    sync.on_gait_part("alpha", slow)
    sync.on_gait_part("kd", 50.0)
    sync.on_gait_timing("at_once", 20)
    assert _answers(sync.on_state(1_500 * MS, q, dq)) == [1_500 * MS]  # a due stamp
    for tick in range(1_501, 1_520):
        assert _answers(sync.on_state(tick * MS, q, dq)) == [tick * MS]
    assert sync.on_state(1_520 * MS, q, dq) == [] and sync.decisions_timed_out == 0


def test_gait_timing_is_parsed_where_it_enters():
    assert parse_gait_timing("next_step") == ("next_step", 0)
    assert parse_gait_timing("at_once:20") == ("at_once", 20)
    assert parse_gait_timing("at_once") == ("at_once", 0)
    for bad in ("sometimes", "at_once:0", "at_once:x", "next_step:20", ""):
        with pytest.raises(ValueError, match="at_once:N"):
            parse_gait_timing(bad)
    with pytest.raises(ValueError, match="gait_timing must be"):
        ControllerDriver(ControllerConfig(), "whenever")


def test_the_timing_log_says_how_gaits_apply_under_the_controllers_settings():
    """The log names what the controller does with an at_once gait: blended (its defaults),
    at once with no blend and no queue (the recovery settings a policy may ask for), or at
    the next touchdown."""
    recovery = ControllerConfig(within_step_blend=0.0, within_step_until=1.0, blend_phase=0.0)
    sync = ControllerDriver(recovery, clock=FakeClock())
    at_once = sync.on_gait_timing("at_once", 20)[0].text
    assert "at once (no blend, no queue)" in at_once and "blended" not in at_once
    assert "next touchdown" in sync.on_gait_timing("next_step", 0)[0].text


def test_a_policy_gone_silent_is_logged_once_with_since_when_and_its_return_too(gaits):
    """No gait part for five decision periods of sim time and a second of wall time: one
    warning (since when, the gait the robot walks on); later silent states say nothing more;
    the next gait part: one line. A policy only behind the simulation (sim time runs on, but
    its gaits keep coming in wall time) is not silent."""
    slow, fast, (q, dq) = gaits
    clock = FakeClock()
    sync = ControllerDriver(ControllerConfig(), clock=clock)
    sync.on_gait_timing("at_once", 20)
    sync.on_gait_part("alpha", slow)
    sync.on_gait_part("kd", 50.0)
    clock.now += 0.9  # 900 ms of wall time: a lagging policy, not a lost one
    for tick in range(0, 300):
        assert not [a for a in sync.on_state(tick * MS, q, dq) if isinstance(a, Log)]
    clock.now += 0.2
    (warning,) = [a for a in sync.on_state(300 * MS, q, dq) if isinstance(a, Log)]
    assert warning.level == "warning" and "the policy is silent: no gait since t = 0.000 s" in warning.text
    assert "every 20 ms" in warning.text and "Kd 50.0" in warning.text
    assert not [a for t in range(301, 400) for a in sync.on_state(t * MS, q, dq) if isinstance(a, Log)]
    (back,) = [a for a in sync.on_gait_part("alpha", fast) if isinstance(a, Log)]
    assert back.level == "info" and "the policy is back" in back.text and "after 0.399 s" in back.text


def test_a_policy_deciding_once_per_step_is_silent_after_two_seconds(gaits):
    slow, _fast, (q, dq) = gaits
    clock = FakeClock()
    sync = ControllerDriver(ControllerConfig(), clock=clock)
    sync.on_gait_part("alpha", slow)
    sync.on_gait_part("kd", 50.0)
    clock.now += 2.0
    logs = [a for t in range(0, 2002) for a in sync.on_state(t * MS, q, dq) if isinstance(a, Log)]
    assert len(logs) == 1 and "since t = 0.000 s" in logs[0].text and "once per step" in logs[0].text


def test_following_the_simulator_no_state_is_answered_before_it_says_how_it_steps(gaits):
    """``mode_known=False`` (``decision_sync`` not given): the first states wait for
    ``/sim/mode``; lockstep turns the hold for due decisions on (a due state then waits for its
    decision), realtime leaves it off; a simulator that never says is waited for 2 s of wall
    time, then the controller answers as given, with one warning."""
    from rabbit_hzd_controller.controller_driver import SIM_MODE_WAIT

    slow, fast, (q, dq) = gaits
    clock = FakeClock()
    sync = ControllerDriver(ControllerConfig(), clock=clock, mode_known=False)
    sync.on_gait_part("alpha", slow)
    sync.on_gait_part("kd", 50.0)
    sync.on_gait_timing("at_once", 20)
    assert sync.on_state(0, q, dq) == [] and sync.missing == ["sim_mode"]
    assert _answers(sync.on_sim_mode(True)) == [0] and sync.decision_sync
    for tick in range(1, 20):
        assert _answers(sync.on_state(tick * MS, q, dq)) == [tick * MS]
    assert sync.on_state(20 * MS, q, dq) == []  # due: held for its decision, as run_stack's controller does
    sync.on_gait_part("alpha", fast)
    assert _answers(sync.on_gait_part("kd", 60.0)) == [20 * MS]
    realtime = ControllerDriver(ControllerConfig(), clock=clock, mode_known=False)
    realtime.on_gait_part("alpha", slow)
    realtime.on_gait_part("kd", 50.0)
    realtime.on_gait_timing("at_once", 20)
    realtime.on_state(0, q, dq)
    assert _answers(realtime.on_sim_mode(False)) == [0] and not realtime.decision_sync
    silent = ControllerDriver(ControllerConfig(), clock=clock, mode_known=False)
    silent.on_gait_part("alpha", slow)
    silent.on_gait_part("kd", 50.0)
    assert silent.on_state(0, q, dq) == [] and silent.check_held() == []
    for _ in range(int(SIM_MODE_WAIT / 0.5) + 1):  # the simulator sends its state again while it waits
        clock.now += 0.5
        actions = silent.on_state(0, q, dq) + silent.check_held()
    assert [type(a) for a in actions] == [Log, Answer] and "did not say how it steps" in actions[0].text


def test_a_policy_back_after_a_reset_is_logged_without_a_negative_duration(gaits):
    """Silent at t = 313 s, the simulation placed again (sim time restarts at 0), then a gait:
    the line says so instead of "after -313.421 s without one" (issue 76)."""
    slow, fast, (q, dq) = gaits
    clock = FakeClock()
    sync = ControllerDriver(ControllerConfig(), clock=clock)
    sync.on_resets(1)
    sync.on_gait_timing("at_once", 20)
    sync.on_gait_part("alpha", slow)
    sync.on_gait_part("kd", 50.0)
    start = 313_000
    sync.on_state(start * MS, q, dq)
    sync.on_gait_part("kd", 50.0)  # the last gait before the silence, at t = 313 s
    clock.now += 2.0
    assert any(isinstance(a, Log) and "silent" in a.text for a in sync.on_state((start + 421) * MS, q, dq))
    sync.on_resets(2)
    sync.on_state(0, q, dq)
    (back,) = [a for a in sync.on_gait_part("alpha", fast) if isinstance(a, Log)]
    assert "the policy is back" in back.text and "-" not in back.text.split("without")[0].split("after")[-1]
    assert "placed again" in back.text


def test_a_controller_that_never_gets_a_state_says_so_once(gaits):
    """A gait is in but no state comes (no simulator, or one whose states do not reach this
    controller): said once, FIRST_STATE_WAIT s after the start, with what it has; never once
    a state came."""
    from rabbit_hzd_controller.controller_driver import FIRST_STATE_WAIT

    slow, _fast, (q, dq) = gaits
    clock = FakeClock()
    sync = ControllerDriver(ControllerConfig(), decision_sync=True, clock=clock)
    sync.on_gait_part("alpha", slow)
    sync.on_gait_part("kd", 50.0)
    sync.on_gait_timing("at_once", 20)
    clock.now += FIRST_STATE_WAIT - 0.1
    assert sync.check_held() == []
    clock.now += 0.2
    (line,) = sync.check_held()
    assert line.level == "info" and "no state on the joint states yet" in line.text and "a gait is in" in line.text
    clock.now += 60.0
    assert sync.check_held() == []  # once
    other = ControllerDriver(ControllerConfig(), clock=clock)
    other.on_state(0, q, dq)  # waits for its gait
    clock.now += 2 * FIRST_STATE_WAIT
    assert all("yet" not in a.text for a in other.check_held())  # (its simulator is silent: said as such)


def test_a_silent_simulator_is_named_within_a_second_and_no_decision_is_waited_for_meanwhile(gaits):
    """A simulator killed while a state waits for its decision: it sends nothing again (a live
    one sends the held state every resend_timeout), so the controller names the simulator,
    not the policy, and counts no lost decision; a state again ends the silence."""
    slow, _fast, (q, dq) = gaits
    clock, sync = _holding_a_due_state(slow, q, dq)
    clock.now += 0.9
    assert sync.check_held() == []
    clock.now += 0.2
    (warning,) = sync.check_held()
    assert warning.level == "warning" and "the simulator is silent" in warning.text and "t = 0.020 s" in warning.text
    clock.now += 5.0
    assert sync.check_held() == [] and sync.decisions_timed_out == 0 and sync.simulator_silences == 1
    back = sync.on_state(20 * MS, q, dq)  # the held state again: it is back, still waiting for its decision
    assert [a.text for a in back if hasattr(a, "text")][0].startswith("the simulator is back")
