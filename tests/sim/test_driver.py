"""sim_node's driver without ROS (rabbit_sim.stepping.SimDriver): events in, actions out,
for the three modes, on the real MuJoCo model with a fake wall clock."""

from __future__ import annotations

import pytest

from rabbit_hzd_controller.gait_state import state_on_gait
from rabbit_msgs_py.pairing import PairingKey, new_key
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_sim.physics.model import load_model
from rabbit_sim.stepping.settings import SimSettings
from rabbit_sim.physics.simulation import Simulator
from rabbit_sim.stepping import (
    FOLLOW_PATIENCE, RECORDER_LAG, SILENCE_WARNING_AFTER, Fallen, Log, Placed, PushApplied, SimDriver, State,
    TorquePublishers, silence_cause)

from fake_clock import FakeClock

pytestmark = pytest.mark.unit

MS = 1_000_000  # ns
C = "hzd_controller_node/cccc"
ZERO = [0.0] * 4


@pytest.fixture(scope="module")
def initial_state() -> tuple[list[float], list[float]]:
    qpos, qvel = state_on_gait(GaitLibrary.load().nearest(1.0).alpha, 1.0)
    return list(qpos), list(qvel)


def _driver(initial_state, clock=None, **settings) -> SimDriver:
    """A driver on ``settings``, paired by ``pairing_key`` if given (else no key, as sim_node's ``none``)."""
    key = PairingKey.parse(settings.get("pairing_key", ""))
    driver = SimDriver(SimSettings(**settings), Simulator(load_model("paper")), clock or FakeClock(), shapes=False,
                       key=key)
    driver.on_initial_state(*initial_state)
    return driver


def _states(actions) -> list[int]:
    return [a.stamp for a in actions if isinstance(a, State)]


def test_lockstep_places_the_robot_then_steps_once_per_reply_to_the_due_state(initial_state):
    driver = SimDriver(SimSettings(), Simulator(load_model("paper")), FakeClock(), shapes=False)
    actions = driver.on_initial_state(*initial_state)
    assert isinstance(actions[0], Placed) and actions[0].count == 1  # /sim/resets before the placed state
    (placed,) = [a for a in actions if isinstance(a, State)]
    assert placed.stamp == 0 and placed.qpos == pytest.approx(initial_state[0])
    assert _states(driver.on_torques(0, C, ZERO, 100.0)) == [MS]
    assert driver.on_torques(0, C, ZERO, 100.0) == []  # a duplicate: answers no state now due
    assert _states(driver.on_torques(MS, C, ZERO, 100.0)) == [2 * MS]
    refused = driver.on_torques(2 * MS, "rogue", [37.0] * 4, 100.0)
    assert _states(refused) == [] and any(isinstance(a, Log) and a.level == "error" for a in refused)
    assert driver.stats.torques_rejected == 1 and driver.sim.time == pytest.approx(0.002)


def test_a_reply_while_paused_steps_when_resumed_and_a_reset_places_again(initial_state):
    driver = _driver(initial_state, start_paused=True)
    actions = driver.on_torques(0, C, ZERO, 100.0)  # held: the step may not run
    assert [a.text for a in actions] == [f"paired with controller {C} at t = 0.000 s"]
    message, actions = driver.on_pause(False)
    assert message == "running" and _states(actions) == [MS]
    ok, message, actions = driver.on_reset("/sim/initial_state")
    assert ok and message == "reset at the next tick" and actions == []  # the reply to t = 1 ms comes first
    actions = driver.on_torques(MS, C, ZERO, 100.0)
    assert [type(a) for a in actions][:1] == [Placed] and _states(actions) == [0] and driver.sim.time == 0.0


def test_with_a_pairing_key_only_signed_torques_move_the_robot_in_every_mode(initial_state):
    key = new_key()
    signer = PairingKey.parse(key)
    for mode in ("lockstep", "realtime"):
        clock = FakeClock()
        driver = _driver(initial_state, clock, mode=mode, pairing_key=key)
        refused = driver.on_torques(0, C, [37.0] * 4, clock.now)  # unsigned, the right stamp
        assert _states(refused) == [] and driver.stats.torques_rejected == 1
        assert "not signed with this stack's pairing key" in refused[-1].text
        actions = driver.on_torques(0, signer.sign(C, 0, ZERO), ZERO, clock.now)
        assert any("paired with controller" in getattr(a, "text", "") for a in actions) and driver.controller == C
        if mode == "lockstep":
            assert _states(actions) == [MS]
        ok, message, _ = driver.on_release_controller()
        assert not ok and "pairing key" in message and driver.controller == C
        if mode == "lockstep":  # a copy of the paired controller's id is named as such, not as the controller
            copied = driver.on_torques(MS, signer.sign(C, 0, ZERO), [37.0] * 4, clock.now + 10.0)
            assert _states(copied) == [] and f"a node that copied the paired controller's id {C}" in copied[-1].text


def test_one_nodes_refused_torques_never_hide_anothers_in_the_log(initial_state):
    """A rogue refused every tick and the real controller refused once (started with another
    key): both refusals are logged, each throttled on its own; past REFUSED_NAMED sources
    (a node inventing a name per reply) the rest share one line."""
    from rabbit_msgs_py.log_lines import LineLogger
    from rabbit_sim.stepping.rules import REFUSED_NAMED

    class Lines(list):
        def error(self, text):
            self.append(text)

    lines = Lines()
    log = LineLogger(lines)
    driver = _driver(initial_state, pairing_key=new_key())
    other = PairingKey.parse(new_key())
    for _ in range(3):
        for action in driver.on_torques(0, "rogue/0000", [37.0] * 4, 100.0):
            log(action)
    for action in driver.on_torques(0, other.sign(C, 0, ZERO), ZERO, 100.0):
        log(action)
    assert len(lines) == 2 and "rogue/0000" in lines[0] and C in lines[1]
    for n in range(3 * REFUSED_NAMED):
        for action in driver.on_torques(0, f"made_up/{n:04d}", ZERO, 100.0):
            log(action)
    assert len(lines) == 2 + (REFUSED_NAMED - 2) + 1  # the named ones, then one line for all the rest
    assert driver.stats.torques_rejected == 4 + 3 * REFUSED_NAMED  # every refusal counted


def test_release_controller_pairs_the_next_to_answer_and_says_so(initial_state):
    driver = _driver(initial_state)
    driver.on_torques(0, C, ZERO, 100.0)
    assert driver.on_torques(MS, "other/dddd", ZERO, 100.0)[-1].level == "error"  # refused
    ok, message, actions = driver.on_release_controller()
    assert ok and C in message and actions[0].level == "warning"
    assert _states(driver.on_torques(MS, "other/dddd", ZERO, 100.0)) == [2 * MS] and driver.controller == "other/dddd"


def test_an_overdue_reply_makes_the_supervisor_send_the_state_again(initial_state):
    clock = FakeClock()
    driver = _driver(initial_state, clock, resend_timeout=0.2)
    asked = []

    def publishers(count: int, alive=None, lapsed: int = 0):
        return lambda: asked.append(1) or TorquePublishers(count, alive, lapsed)

    assert driver.supervise(publishers(1)) == []
    clock.now += 0.3
    actions = driver.supervise(publishers(0))
    assert _states(actions) == [0] and not any(isinstance(a, Log) for a in actions) and not asked  # re-sent, quietly
    clock.now += SILENCE_WARNING_AFTER  # then it says why, naming the cause
    (log,) = [a for a in driver.supervise(publishers(0)) if isinstance(a, Log)]
    assert "no node publishes /joint_torques" in log.text and "re-sending it every 0.2 s" in log.text
    assert log.level == "info"  # no controller has answered yet: a start (nodes come up seconds apart), not a fault


def test_the_silence_warning_names_the_silent_controller_and_the_one_to_release(initial_state):
    """The paired controller is killed and another started by hand without a key: the
    warning once said the dead one "is alive but has not answered", crediting it with the
    new one's liveliness, and the remedy was on another line. It names both, and the
    service that pairs the new one, in one line."""
    clock = FakeClock()
    driver = _driver(initial_state, clock, resend_timeout=0.2)
    assert _states(driver.on_torques(0, C, ZERO, clock.now)) == [MS]  # C paired, answering
    clock.now += 0.3
    driver.on_torques(MS, "hzd_controller_node/eeee", ZERO, clock.now)  # the new one answers: refused
    clock.now += SILENCE_WARNING_AFTER
    (log,) = [a for a in driver.supervise(lambda: TorquePublishers(2, 1, 1)) if isinstance(a, Log)]
    line = log.text
    assert log.level == "warning"  # a controller that answered has gone silent: a fault
    assert f"controller {C} has not answered" in line and "is alive" not in line
    assert "controller hzd_controller_node/eeee answers but is not paired" in line
    assert "ros2 service call /sim/release_controller std_srvs/srv/Trigger" in line
    _ok, _message, _actions = driver.on_release_controller()
    assert _states(driver.on_torques(MS, "hzd_controller_node/eeee", ZERO, clock.now)) == [2 * MS]


def test_the_silence_warning_names_the_cause():
    topic, gait = "/joint_torques", "/hzd/alpha and /hzd/kd"
    assert "no node publishes" in silence_cause(TorquePublishers(0), C, topic, gait)
    assert f"controller {C} stopped or died" in silence_cause(TorquePublishers(1, 0, 1), C, topic, gait)
    assert "is alive but has not answered" in silence_cause(TorquePublishers(2, 1, 0), C, topic, gait)
    assert "is busy, or died" in silence_cause(TorquePublishers(1), None, topic, gait)  # no liveliness declared


def test_paced_states_wait_for_their_wall_time(initial_state):
    clock = FakeClock()
    driver = _driver(initial_state, clock, mode="paced", rtf=1.0)
    assert _states(driver.on_torques(0, C, ZERO, clock.now)) == []  # t = 1 ms is due 1 ms after the start
    assert _states(driver.paced_wake()) == []
    clock.now += 0.001
    assert _states(driver.paced_wake()) == [MS]
    assert driver.paced_wake() == []


@pytest.mark.parametrize("paused_first", [False, True])
def test_paced_time_spent_waiting_for_a_first_reply_is_not_made_up_by_running_fast(initial_state, paused_first):
    """A controller that answers the placed state 40 ms late (a busy machine), after the start
    or after a resume, must not let the next 40 ms x rtf of sim time go out at once."""
    clock = FakeClock()
    driver = _driver(initial_state, clock, mode="paced", rtf=4.0)
    if paused_first:
        driver.on_pause(True)
        clock.now += 1.0
        driver.on_pause(False)
    clock.now += 0.040
    stamp, burst = 0, 0
    for _ in range(100):  # a controller that answers at once; the clock moves only while a state waits
        sent = _states(driver.on_torques(stamp, C, ZERO, clock.now))
        if not sent:
            clock.now += driver.pace_wait + 1e-9  # (a timer fires at, or just after, its time)
            sent = _states(driver.paced_wake())
        elif stamp:
            burst += 1
        (stamp,) = sent
    assert burst == 0  # every state after the first step waited for its wall time
    assert driver.statistics()["achieved_rtf"] == pytest.approx(4.0, rel=1e-6)


def test_recorder_lag_holds_lockstep_until_the_recorder_catches_up(initial_state):
    driver = _driver(initial_state, wait_for_recorder=True)
    driver.on_recorded(0)
    lag = RECORDER_LAG + 1  # states the recorder may lag behind, and the one it waits for
    for tick in range(lag):
        assert _states(driver.on_torques(tick * MS, C, ZERO, 100.0)) == [(tick + 1) * MS]
    assert driver.on_torques(lag * MS, C, ZERO, 100.0) == []  # the recorder is too far behind
    assert _states(driver.on_recorded(MS)) == [(lag + 1) * MS]


def test_realtime_holds_the_start_until_a_torque_then_steps_by_the_wall_clock(initial_state):
    clock = FakeClock()
    driver = _driver(initial_state, clock, mode="realtime", watchdog_timeout=0.008)
    clock.now += 0.0105
    assert driver.sim.time == 0.0 and _states(driver.realtime_wake()) == [0]  # held, re-sent every 10 ticks
    driver.on_torques(0, C, ZERO, clock.now)
    clock.now += 0.001
    actions = driver.realtime_wake()
    assert _states(actions) and driver.sim.time > 0.0
    clock.now += 0.02  # no torque for 20 ms: damping, said once
    tripped = [a for _ in range(3) for a in driver.realtime_wake() if isinstance(a, Log) and "watchdog" in a.text]
    assert len(tripped) == 1 and driver.watchdog.active


def test_a_push_is_applied_and_reported_and_a_bad_one_refused(initial_state):
    driver = _driver(initial_state)
    actions = driver.on_push(-50.0, 0.0, 0.0)
    assert [a.wrench for a in actions if isinstance(a, PushApplied)] == [(-50.0, 0.0, 0.0)]
    refused = driver.on_push(float("nan"), 0.0, 0.0)
    assert driver.pushes_rejected == 1 and [a.level for a in refused] == ["error"]


def test_a_fall_halts_the_physics_until_a_reset(initial_state):
    driver = _driver(initial_state)
    stamp, fell = 0, []
    while not fell and stamp < 3000 * MS:  # no torque: RABBIT collapses
        actions = driver.on_torques(stamp, C, ZERO, 100.0)
        fell = [a for a in actions if isinstance(a, Fallen)]
        stamp += MS
    assert fell == [Fallen(True)] and driver.halted and driver.fallen
    assert driver.on_torques(stamp, C, ZERO, 100.0) == []  # halted: nothing steps
    ok, _message, actions = driver.on_reset("/sim/initial_state")
    assert ok and Fallen(False) in actions and _states(actions) == [0] and not driver.halted


def test_stop_time_halts_the_physics(initial_state):
    driver = _driver(initial_state, stop_time=0.003)
    for tick in range(3):
        actions = driver.on_torques(tick * MS, C, ZERO, 100.0)
    assert driver.halted and not driver.fallen and any("stop_time" in a.text for a in actions if isinstance(a, Log))
    assert driver.on_torques(3 * MS, C, ZERO, 100.0) == []


def test_a_recorder_that_turns_up_is_followed_and_one_that_stalls_is_let_go(initial_state):
    """Without wait_for_recorder (a recorder started by hand): a recorder's announcement (a
    negative stamp) makes lockstep wait for it; one that keeps the simulation waiting
    FOLLOW_PATIENCE s is let go with a warning (a stalled recorder, or a node that only
    announces one, must not hold the robot for good), and none is followed until every
    publisher of the reports has left; then a new one is followed again."""
    clock = FakeClock()
    driver = _driver(initial_state, clock, resend_timeout=0.2)
    recorders = [1]
    count = lambda: recorders[0]  # noqa: E731
    driver.on_recorded(-1_000_000_000)  # "here, nothing written yet"
    assert driver.recorder.following
    assert _states(driver.on_torques(0, C, ZERO, clock.now)) == [] and driver.sim.time == 0.0  # held for the recorder
    driver.supervise(lambda: TorquePublishers(1), count)  # starts the wait
    clock.now += FOLLOW_PATIENCE
    logs = [a for a in driver.supervise(lambda: TorquePublishers(1), count) if isinstance(a, Log)]
    assert any(a.level == "warning" and "has not kept up for 5 s" in a.text for a in logs), logs
    assert not driver.recorder.following and round(driver.sim.time, 9) == 0.001  # the held step ran
    driver.on_recorded(-1_000_000_000)  # the same node announcing again: not followed
    assert not driver.recorder.following
    recorders[0] = 0
    driver.supervise(lambda: TorquePublishers(1), count)  # every publisher has left
    recorders[0] = 1
    driver.on_recorded(-1_000_000_000)  # a new recorder
    assert driver.recorder.following
