"""The ROS 2 node stack through faults: resets, a rogue on /joint_torques, a policy that stops
deciding or is killed, a controller stopped, killed or restarted, the realtime watchdog, many
callers of the services at once, and the supervisor's stall rule."""

from __future__ import annotations

import time

import numpy as np
import pytest
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.pairing import new_key
from rabbit_msgs_py.service_callers import service_clients
from rabbit_policy.policy_node import PolicyNode
from rabbit_policy.bringup import processes as processes_module
from rabbit_policy.bringup.config import StackConfig
from rabbit_policy.bringup.processes import run_multi_process
from rabbit_sim.sim_node import SimNode

from ros_helpers import ros_context, spin_for, spin_until, spinning, wait_until
from stack_helpers import call_service, residual_policy_file, start_sim_and_policy, start_stack

pytestmark = pytest.mark.ros


@pytest.mark.slow
def test_reset_service_puts_the_robot_back_on_the_gait():
    with ros_context() as (context, executor):
        import rclpy

        nodes = start_stack(context, executor)
        sim = nodes["sim"]
        assert spin_until(executor, lambda: sim.time >= 1.0)
        resetter = rclpy.create_node("resetter", context=context)
        executor.add_node(resetter)
        client = resetter.create_client(Trigger, topics.RESET_SERVICE)
        assert spin_until(executor, client.service_is_ready)
        future = client.call_async(Trigger.Request())
        assert spin_until(executor, future.done)
        assert future.result().success
        assert spin_until(executor, lambda: sim.time < 0.5)
        x_after_reset = float(sim.sim.data.qpos[0])
        assert x_after_reset < 0.3
        assert spin_until(executor, lambda: sim.time >= 1.5)
        assert not sim.fallen
        assert nodes["controller"].controller.steps >= 2  # restarted, walking again


def test_a_strangers_reset_and_pause_are_logged_with_when_and_who(capfd):
    """A node of another process (its own context) calls /sim/reset and /sim/pause: the
    simulator logs each with the sim time and the nodes holding a client of the service (the
    caller among them); a burst is one line a second, the next line counting the calls between
    (every call counted, whatever the timing)."""
    import re

    import rclpy
    from std_srvs.srv import SetBool

    from fake_clock import FakeClock
    from rabbit_msgs_py.service_callers import LOOKUP_EVERY, CallerLog, service_clients

    with ros_context() as (context, executor), ros_context() as (ctx_s, ex_s):
        sim = SimNode(context=context)
        executor.add_node(sim)
        stranger = rclpy.create_node("stranger", context=ctx_s)
        ex_s.add_node(stranger)
        reset = stranger.create_client(Trigger, topics.RESET_SERVICE)
        pause = stranger.create_client(SetBool, topics.PAUSE_SERVICE)
        assert spin_until((executor, ex_s), lambda: reset.service_is_ready() and pause.service_is_ready(), 30.0)
        assert spin_until((executor, ex_s), lambda: all(service_clients(sim, s) == ["/stranger"] for s in (
            topics.RESET_SERVICE, topics.PAUSE_SERVICE)), 30.0)  # the graph has the caller (the call may beat it)
        for client, request in ((reset, Trigger.Request()), (reset, Trigger.Request()), (reset, Trigger.Request()),
                                (pause, SetBool.Request(data=True))):
            future = client.call_async(request)
            assert spin_until((executor, ex_s), future.done, 30.0)
        spin_for((executor, ex_s), LOOKUP_EVERY + 0.1)
        future = reset.call_async(Trigger.Request())
        assert spin_until((executor, ex_s), future.done, 30.0)
        lines = [line for line in capfd.readouterr().err.splitlines() if " called (" in line]
        resets = [line for line in lines if "/sim/reset called (reset)" in line]
        (paused,) = [line for line in lines if "/sim/pause called (pause)" in line]
        assert "at t = 0.000 s; nodes with a client of it: /stranger" in resets[0] and "/stranger" in paused
        # every call counted, however fast this machine made the burst: a line each, or in the next line's count
        more = [int(m.group(1)) if (m := re.search(r"\((\d+) more calls since the last line\)$", line)) else 0
                for line in resets]
        assert len(resets) + sum(more) == 4, resets
        clock = FakeClock()  # the rule itself, on this node's graph: a line a second, the calls between counted
        log = CallerLog(sim, clock)
        for _ in range(3):
            log(topics.RESET_SERVICE, "reset", 1.0)
        clock.now += LOOKUP_EVERY
        log(topics.RESET_SERVICE, "reset", 2.0)
        lines = [line for line in capfd.readouterr().err.splitlines() if " called (" in line]
        assert len(lines) == 2 and "t = 1.000 s" in lines[0] and "/stranger" in lines[0]
        assert "t = 2.000 s" in lines[1] and lines[1].endswith("(2 more calls since the last line)")


def test_run_stacks_report_names_a_strangers_reset_with_when_and_who():
    """A stranger (another process's context) resets the simulation under a run's supervisor:
    the run is not complete, and its report says when and which nodes held a client of
    /sim/reset then (the stranger among them), as its log line does."""
    import rclpy

    from rabbit_policy.bringup.supervisor import Supervisor

    with ros_context() as (context, executor), ros_context() as (ctx_s, ex_s):
        nodes = start_stack(context, executor, start_paused=True)  # placed at t = 0, paused
        supervisor = Supervisor(StackConfig(duration=10.0, schedule=((0.0, 1.0),), pairing_key=""), context=context)
        executor.add_node(supervisor)
        stranger = rclpy.create_node("stranger", context=ctx_s)
        ex_s.add_node(stranger)
        reset = stranger.create_client(Trigger, topics.RESET_SERVICE)
        assert spin_until((executor, ex_s), reset.service_is_ready, 30.0)
        assert spin_until((executor, ex_s), lambda: supervisor._placements is not None, 30.0)  # the first placement
        assert spin_until((executor, ex_s), lambda: "/stranger" in service_clients(supervisor, topics.RESET_SERVICE),
                          30.0)
        future = reset.call_async(Trigger.Request())
        assert spin_until((executor, ex_s), lambda: future.done() and supervisor.resets == 1, 30.0)
        report = supervisor.report()
        assert not report.completed and report.error.startswith("the simulation was reset 1 time during the run")
        assert "t = 0.000 s, by /stranger" in report.error, report.error
        for node in (*nodes.values(), supervisor, stranger):
            node.destroy_node()


def test_resets_never_wedge_lockstep():
    """Back-to-back resets, and a reset while paused at t = 0 followed by unpausing: the
    placed state equals the one the controller already answered, yet it is answered (the
    reset is an event the controller hears, not inferred from stamps or values)."""
    from std_srvs.srv import SetBool

    with ros_context() as (context, executor):
        import rclpy

        nodes = start_stack(context, executor, start_paused=True)
        sim = nodes["sim"]
        user = rclpy.create_node("resetter", context=context)
        executor.add_node(user)
        reset = user.create_client(Trigger, topics.RESET_SERVICE)
        pause = user.create_client(SetBool, topics.PAUSE_SERVICE)
        assert spin_until(executor, lambda: reset.service_is_ready() and pause.service_is_ready())
        assert spin_until(executor, lambda: sim.lockstep.held_torques is not None)  # t = 0 answered, paused
        assert call_service(executor, reset, Trigger.Request()).success  # a reset while paused at t = 0
        assert call_service(executor, pause, SetBool.Request(data=False)).success
        assert spin_until(executor, lambda: sim.time >= 0.3, timeout=10.0), f"stuck at t = {sim.time}"
        for _ in range(20):  # back to back
            assert call_service(executor, reset, Trigger.Request()).success
        assert spin_until(executor, lambda: sim.time >= 0.3, timeout=10.0), f"stuck at t = {sim.time}"
        assert not sim.fallen


ROGUE_TORQUE = 37.0


def _rogue(node, kind: str) -> list:
    """Make ``node`` a rogue on /joint_torques: ``stale`` sends 37 N m at 1 kHz stamped with
    the newest state it saw minus 1 ms; ``echo`` answers every state with its exact stamp
    under a name of its own (a second controller that computes nonsense). Returns a flag
    list: clear it to silence the rogue."""
    from rabbit_msgs_py.conversions import torques_to_msg

    active, latest = [True], {}
    publisher = node.create_publisher(JointState, topics.JOINT_TORQUES, qos.STREAM_QOS)

    def on_state(m):
        latest["stamp"] = m.header.stamp
        if active and kind == "echo":
            publisher.publish(torques_to_msg([ROGUE_TORQUE] * 4, m.header.stamp, "rogue/0000"))

    def send():
        if active and kind == "stale" and "stamp" in latest:
            msg = torques_to_msg([ROGUE_TORQUE] * 4, latest["stamp"])
            msg.header.stamp.nanosec = max(0, msg.header.stamp.nanosec - 1_000_000)
            publisher.publish(msg)

    node.create_subscription(JointState, topics.JOINT_STATES, on_state, qos.STREAM_QOS)
    node.create_timer(0.001, send)
    return active


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["stale", "echo"])
def test_a_rogue_that_starts_mid_run_never_gets_a_torque_applied(kind):
    """A rogue publisher starts on /joint_torques while the stack walks, six times: no state
    ever shows its torque applied (every applied effort is recorded), the walk goes on.
    Simulator, rogue and controller each have a context of their own; the controller's is
    spun only after the simulator has refused the ``echo`` rogue's answer to the state (or
    0.5 s, while a new rogue is discovered), so the echo comes before the controller's: its
    replies carry the right stamp and are refused for their source, not merely late. (A fixed
    5 ms head start let the controller answer first on a busy machine: none refused.)"""
    with ros_context() as (context, executor), ros_context() as (ctx_r, ex_r), \
            ros_context() as (ctx_c, ex_c):
        import rclpy

        nodes = start_sim_and_policy(context, executor)
        controller = HZDControllerNode(context=ctx_c)
        ex_c.add_node(controller)
        sim = nodes["sim"]
        efforts: list = []
        watcher = rclpy.create_node("effort_watcher", context=context)
        watcher.create_subscription(JointState, topics.JOINT_STATES,
                                    lambda m: efforts.append(list(m.effort[3:])), qos.STREAM_QOS)
        executor.add_node(watcher)
        spun = (executor, ex_r, ex_c)
        assert spin_until(spun, lambda: sim.time >= 0.2)
        for attempt in range(6):  # each a new node that starts mid-run, then falls silent
            rogue = rclpy.create_node(f"rogue_{attempt}", context=ctx_r)
            active = _rogue(rogue, kind)
            ex_r.add_node(rogue)
            start, deadline = sim.time, time.monotonic() + 60.0
            while sim.time < start + 0.05:
                assert time.monotonic() < deadline, f"stuck at {sim.time}"
                if kind == "echo":  # the rogue's reply reaches the simulator first, however busy the CPUs
                    rejected = sim.torques_rejected
                    spin_until((executor, ex_r), lambda: sim.torques_rejected > rejected, timeout=0.5)
                else:
                    spin_for((executor, ex_r), 0.005)
                spin_for(ex_c, 0.005)  # all it has queued: one callback a turn fell behind the re-sent states
            active.clear()
        if kind == "echo":
            assert sim.torques_rejected > 0  # right stamp, wrong controller: refused
        assert not sim.fallen
        assert efforts and all(abs(e - ROGUE_TORQUE) > 1e-9 for row in efforts for e in row)
        assert sim.controller == controller.source


@pytest.mark.slow
def test_a_policy_that_stops_deciding_never_wedges_decision_sync():
    """Lockstep with decision_sync: the policy node goes away mid-walk, so the decision
    due on the next 20th tick never comes. The controller gives it up after
    decision_timeout, answers with the gait in force (once: later due states do not
    wait) and the walk goes on."""
    with ros_context() as (context, executor):
        nodes = start_sim_and_policy(context, executor)
        sim, policy = nodes["sim"], nodes["policy"]
        controller = HZDControllerNode(context=context, decision_sync=True, decision_timeout=0.3)
        executor.add_node(controller)
        assert spin_until(executor, lambda: sim.time >= 0.5)
        assert controller.decisions_waited >= 20 and controller.decisions_timed_out == 0
        executor.remove_node(policy)  # no longer spun: it decides nothing more
        try:
            stopped = sim.time
            assert spin_until(executor, lambda: sim.time >= stopped + 1.0)
            assert controller.decisions_timed_out == 1 and not sim.fallen
        finally:  # ros_context destroys only the executor's nodes: one left alive outlives the test in
            policy.destroy_node()  # the domain, and a later run_stack there refuses to start beside it


@pytest.mark.slow
def test_a_killed_policy_is_named_by_the_controller_within_two_seconds(capfd):
    """Nodes started by hand, the controller with ``decision_sync:=false`` (the robot walks on
    the last gait; in lockstep it would hold the due state for ``decision_timeout`` first): the policy's
    process dies (its context shut down). The controller logs one warning that the policy is
    silent, since when and on which gait it walks, within 2 s of wall time (five decisions of
    sim time and a second of wall time without a gait); nothing more while it stays silent. A
    policy that is only behind the simulation is not reported (tests/hzd_controller)."""
    with ros_context() as (context, executor), ros_context() as (ctx_p, ex_p):
        sim = SimNode(context=context)
        controller = HZDControllerNode(context=context, decision_sync=False)
        for node in (sim, controller):
            executor.add_node(node)
        ex_p.add_node(PolicyNode(context=ctx_p))
        assert spin_until((executor, ex_p), lambda: sim.time >= 0.5, timeout=60.0)
        capfd.readouterr()
        ctx_p.try_shutdown()  # kill -9: nothing more from it
        killed = time.monotonic()
        lines: list[str] = []
        while time.monotonic() < killed + 2.0 and not lines and not sim.halted:
            spin_for(executor, 0.05)
            lines += [line for line in capfd.readouterr().err.splitlines() if "the policy is silent" in line]
        assert len(lines) == 1, lines
        assert "[hzd_controller_node]" in lines[0] and "walking on the last gait" in lines[0]
        spin_for(executor, 1.5)
        assert "the policy is silent" not in capfd.readouterr().err  # once, not again


@pytest.mark.slow
def test_controller_restart_mid_walk_lockstep_waits_and_resumes():
    """With no pairing key (``pairing_key:=none``, unsafe): the robot waits for its controller; a
    new controller is paired only after ``/sim/release_controller`` (an explicit act, never
    silence). With a key (the stack's or the user's) see test_intruders.py."""
    # the controller lives in a context of its own, standing in for its own process
    with ros_context() as (context, executor):
        import rclpy

        nodes = start_sim_and_policy(context, executor, resend_timeout=0.1, pairing_key="none")
        sim = nodes["sim"]
        user = rclpy.create_node("user", context=context)
        executor.add_node(user)
        release = user.create_client(Trigger, topics.RELEASE_CONTROLLER_SERVICE)
        with ros_context() as (ctx_a, ex_a):
            old = HZDControllerNode(context=ctx_a, pairing_key="none")
            ex_a.add_node(old)
            assert spin_until((executor, ex_a), lambda: sim.time >= 1.0)
            old_source = old.source
        # controller "process" gone: its context is shut down (a reply in flight may land)
        spin_for(executor, 0.05)
        t_stopped = sim.time
        spin_for(executor, 0.5)
        assert sim.time == t_stopped  # lockstep: the physics waits for a torque
        assert sim.resends >= 2
        with ros_context() as (ctx_b, ex_b):
            new = HZDControllerNode(context=ctx_b, pairing_key="none")
            ex_b.add_node(new)
            assert spin_until((executor, ex_b), lambda: new.torques_published > 0)
            spin_for((executor, ex_b), 0.5)
            assert sim.time == t_stopped and sim.controller == old_source  # answered, refused: still paired
            assert spin_until((executor, ex_b), release.service_is_ready)
            future = release.call_async(Trigger.Request())
            assert spin_until((executor, ex_b), future.done) and future.result().success
            assert spin_until((executor, ex_b), lambda: sim.time >= t_stopped + 0.5)
            assert not sim.fallen
            assert sim.controller == new.source  # the new instance, after the explicit release


@pytest.mark.slow
def test_a_stopped_or_killed_controller_is_named_as_such(capfd):
    """The controller process is SIGSTOPped mid-walk, then SIGCONTed, then SIGKILLed. DDS
    keeps a killed node listed for its lease (up to 20 s), so "no node publishes" cannot
    tell; the controller's torque publisher declares a 1 s liveliness lease, and the
    simulator's warning says the controller stopped or died (not that it is busy) once the
    lease has lapsed as the simulator sees it (DDS may deliver the lapse late on a busy
    machine; a warning before it rightly says the controller is alive). After SIGCONT the walk
    goes on with the same controller."""
    import os
    import signal
    import subprocess
    import sys

    # a domain of its own: the killed process stays in the graph for its lease (20 s), and a
    # later test's run_stack would take it for another stack
    domain = (int(os.environ.get("ROS_DOMAIN_ID", "0")) + 50) % 101 + 110
    key = new_key()

    def warnings_within(seconds: float) -> list[str]:
        found: list[str] = []
        deadline = time.monotonic() + seconds  # the warning is throttled to one per 5 s
        while not found and time.monotonic() < deadline:
            spin_for(executor, 0.5)
            found = [line for line in capfd.readouterr().err.splitlines() if "re-sending it" in line]
        return found

    def lapsed() -> bool:  # the simulator's own view of the torque publishers' liveliness
        publishers = sim._torque_publishers()
        return publishers.alive == 0 and publishers.lapsed > 0

    with ros_context(domain_id=domain) as (context, executor):
        nodes = start_sim_and_policy(context, executor, resend_timeout=0.1, pairing_key=key)
        sim = nodes["sim"]
        proc = subprocess.Popen([sys.executable, "-m", "rabbit_hzd_controller.hzd_controller_node", "--ros-args",
                                 "-p", f"pairing_key:={key}"],
                                env={**os.environ, "ROS_DOMAIN_ID": str(domain)},
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            assert spin_until(executor, lambda: sim.time >= 0.3, timeout=60.0)
            # the simulator learns that the controller is alive from its writers' liveliness (its
            # participant announces it within about a second of matching): only a controller seen
            # alive can be seen to lapse (one stopped before is "busy, or died")
            assert spin_until(executor, lambda: sim._torque_publishers().alive == 1, timeout=30.0)
            controller = sim.controller
            os.kill(proc.pid, signal.SIGSTOP)
            assert spin_until(executor, lapsed, timeout=30.0), (sim._liveliness, sim._torque_publishers())
            capfd.readouterr()  # what was logged before the lease lapsed
            stopped = warnings_within(30.0)
            os.kill(proc.pid, signal.SIGCONT)
            t_resumed = sim.time
            assert spin_until(executor, lambda: sim.time >= t_resumed + 0.2, timeout=60.0)
            assert sim.controller == controller
            assert spin_until(executor, lambda: not lapsed(), timeout=30.0)  # alive again
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
            assert spin_until(executor, lapsed, timeout=30.0), (sim._liveliness, sim._torque_publishers())
            capfd.readouterr()
            killed = warnings_within(30.0)
        finally:
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGCONT)
                proc.kill()
    for found in (stopped, killed):
        assert found, "no re-send warning"
        assert f"controller {controller} stopped or died" in found[0], found[0]


@pytest.mark.slow
def test_realtime_watchdog_damps_while_the_controller_is_gone():
    # each context spins in a thread of its own, standing in for a process
    with ros_context() as (context, executor):
        import rclpy

        # max_late_fraction 1: never halt for lateness here, this test is about the watchdog
        key = new_key()  # the stack's: the controller it starts again is paired (test_intruders.py)
        nodes = start_sim_and_policy(context, executor, mode="realtime", watchdog_timeout=0.05,
                                      max_late_fraction=1.0, pairing_key=key)
        sim = nodes["sim"]
        helper = rclpy.create_node("resetter", context=context)
        executor.add_node(helper)
        reset = helper.create_client(Trigger, topics.RESET_SERVICE)
        with spinning(executor):
            with ros_context() as (ctx_a, ex_a), spinning(ex_a):
                ex_a.add_node(HZDControllerNode(context=ctx_a, pairing_key=key))
                assert wait_until(lambda: sim.time >= 1.0)
                assert not sim.fallen
            # controller gone: damping takes over within the watchdog timeout; without a
            # controller the underactuated robot may still collapse (the physics then halts)
            damped_before = sim.damped_ticks
            time.sleep(0.3)
            # damping took over (and holds unless the robot went down: the physics halts)
            assert sim.damped_ticks > 0 and (sim.damped_ticks - damped_before > 20 or sim.fallen)
            assert sim.watchdog.active or sim.fallen
            with ros_context() as (ctx_b, ex_b), spinning(ex_b):
                ex_b.add_node(HZDControllerNode(context=ctx_b, pairing_key=key))
                # start again from the gait (the robot is falling or down by now)
                future = reset.call_async(Trigger.Request())
                assert wait_until(future.done) and future.result().success
                received = sim.torques_received
                # torques flow again, damping is off and the robot walks on
                assert wait_until(lambda: sim.torques_received > received + 500, 10.0), sim.statistics()
                assert not sim.fallen and not sim.watchdog.active


@pytest.mark.slow
def test_many_callers_of_reset_and_pause_at_once_are_each_answered():
    """Bursts as in issue 39: one client calls /sim/reset 300 times at once and another
    /sim/pause (false) 200 times, from a context of their own, with the clients made as
    docs/faults.md says (``rabbit_msgs_py.qos.SERVICE_QOS``): every call is served and
    answered, and the stack walks on. (With rclpy's default client the server still serves
    all, but the caller's own history keeps 10 answers: see rabbit_msgs_py.qos.)"""
    from std_srvs.srv import SetBool

    with ros_context() as (context, executor), ros_context() as (ctx_u, ex_u):
        import rclpy

        nodes = start_stack(context, executor)
        sim = nodes["sim"]
        users = [rclpy.create_node(f"caller_{i}", context=ctx_u) for i in range(2)]
        reset = users[0].create_client(Trigger, topics.RESET_SERVICE, qos_profile=qos.SERVICE_QOS)
        pause = users[1].create_client(SetBool, topics.PAUSE_SERVICE, qos_profile=qos.SERVICE_QOS)
        for user in users:
            ex_u.add_node(user)
        assert spin_until((executor, ex_u), lambda: reset.service_is_ready() and pause.service_is_ready()
                          and sim.time > 0.1)
        futures = [reset.call_async(Trigger.Request()) for _ in range(300)]
        futures += [pause.call_async(SetBool.Request(data=False)) for _ in range(200)]
        assert spin_until((executor, ex_u), lambda: all(f.done() for f in futures), timeout=60.0), \
            f"{sum(f.done() for f in futures)} of {len(futures)} answered"
        assert all(f.result().success for f in futures)
        start = sim.time
        assert spin_until(executor, lambda: sim.time >= start + 0.3) and not sim.fallen


def _state(t: float, x: float) -> bytes:
    """A one-state ``/sim/state_batch`` message as the supervisor takes it (serialized): the
    state at ``t`` s with the hip at ``x`` m."""
    import array

    from rclpy.serialization import serialize_message

    from rabbit_msgs_py.conversions import state_batch_to_msg

    return serialize_message(state_batch_to_msg(array.array("d", [round(t * 1e9), x, 0.75] + [0.0] * 19), 1))


def _step(t: float):

    from rabbit_msgs_py.conversions import stamp_from_ns

    return Header(stamp=stamp_from_ns(round(t * 1e9)), frame_id="left_foot")


def test_late_touchdown_events_are_not_a_stall_and_a_real_stall_still_ends_the_run(monkeypatch):
    """The supervisor's callbacks in the order a loaded machine delivered them: the states
    run 2.5 s past the last touchdown event while three touchdowns are still on their way
    (a lost reliable sample waits for the writer's next heartbeat, and the events behind it
    with it). They arrive late: no stall. With no event at all a stall counts once the grace
    is over, at the sim time it was suspected, and the walk ends there."""
    from rabbit_policy.bringup import supervisor as module

    with ros_context() as (context, _executor):
        config = StackConfig(duration=10.0, schedule=((0.0, 1.0),), pairing_key="")  # unsigned batches, by hand
        late = module.Supervisor(config, context=context)
        ticks = np.round(np.arange(0.0, 3.5005, 0.001), 3)
        for t in ticks:
            late._on_batch(_state(t, t))
            if t in (0.5, 1.0):
                late._count_step(_step(t - 0.001))
        assert not late.stalled and late._suspected is not None and not late.done  # suspected, not concluded
        for t in (1.6, 2.2, 2.8):
            late._count_step(_step(t))  # the late ones
        assert late._suspected is None and not late.stalled
        monkeypatch.setattr(module, "EVENT_GRACE", 0.2)
        time.sleep(0.3)
        assert not late.done and not late.stalled  # nothing to settle: the run goes on

        stalled = module.Supervisor(config, context=context)
        for t in ticks:
            stalled._on_batch(_state(t, t))
            if t == 1.0:
                stalled._count_step(_step(t - 0.001))
        assert not stalled.stalled
        time.sleep(0.3)  # the grace passes with no event
        assert stalled.done and stalled.stalled and stalled.stall_time == pytest.approx(3.001)
        result = stalled.result()
        assert result.stalled and result.times[-1] == pytest.approx(3.001)  # ends at the stall

        gappy = module.Supervisor(config, context=context)  # it missed the states around the stall (load)
        for t in ticks:
            if not 2.95 < t < 3.033:
                gappy._on_batch(_state(t, t))
            if t == 1.0:
                gappy._count_step(_step(t - 0.001))
        time.sleep(0.3)
        assert gappy.done and gappy.stall_time == 3.001  # dated at the tick the rule fired, not at 3.033
        for node in (late, stalled, gappy):
            node.destroy_node()


def test_the_supervisor_counts_sim_time_in_the_stamps_integer_ns():
    """A duration off the ms grid ends at its last whole tick, where sim_node stops
    (``on_tick_grid``: 0.3004 s -> 0.300 s; the supervisor once waited for 0.3004 - 1e-9 s,
    which never came); the result's times and touchdowns are the stamps' ns as seconds, on the
    ns grid, equal to the fast path's (``round(n * 0.001, 9)``)."""
    from rabbit_policy.bringup import supervisor as module

    with ros_context() as (context, _executor):
        supervisor = module.Supervisor(StackConfig(duration=0.3004, schedule=((0.0, 1.0),), pairing_key=""),
                                       context=context)  # unsigned batches, made by hand
        for n in range(301):
            supervisor._on_batch(_state(n / 1000, n / 1000))
            if n == 100:
                supervisor._count_step(_step(0.099))
            assert supervisor.done == (n == 300), n
        result = supervisor.result()
        assert list(result.times) == [round(n * 0.001, 9) for n in range(1, 301)]
        assert [touchdown.time for touchdown in result.touchdowns] == [0.1]
        supervisor.destroy_node()


@pytest.mark.slow
def test_a_body_state_policy_walks_on_through_resets(tmp_path):
    """Resets mid-step while a body-state decision may be waiting for its parts: policy_node
    forgets the last walk's states, phases and waiting decisions, decides again on the new
    walk's, and gives none up."""
    path = residual_policy_file(tmp_path / "body_kind.pt", features="body")
    with ros_context() as (context, executor):
        import rclpy

        nodes = {"policy": PolicyNode(context=context, policy="learned", policy_file=path),
                 "controller": HZDControllerNode(context=context), "sim": SimNode(context=context)}
        for node in nodes.values():
            executor.add_node(node)
        sim, policy = nodes["sim"], nodes["policy"]
        user = rclpy.create_node("resetter", context=context)
        executor.add_node(user)
        reset = user.create_client(Trigger, topics.RESET_SERVICE)
        assert spin_until(executor, reset.service_is_ready)
        for until in (0.35, 0.123, 0.261):  # mid-step, between decisions
            assert spin_until(executor, lambda: sim.time >= until, timeout=30.0), f"stuck at t = {sim.time}"
            decided = policy.decisions
            assert call_service(executor, reset, Trigger.Request()).success
        assert spin_until(executor, lambda: sim.time >= 0.5, timeout=30.0), f"stuck at t = {sim.time}"
        assert policy.decisions >= decided + 20  # every 20 ticks on the new walk
        assert policy.decisions_given_up == 0 and not sim.fallen
        assert policy.body.newest_state <= 0.6e9  # the new walk's states only


def test_a_composed_node_that_cannot_start_ends_the_run_with_its_line_and_leaves_no_process(monkeypatch):
    """run_stack's default layout builds the simulator in its own process: one that cannot start
    (here its viewer without a display) raises its one line after the policy process started,
    and that process is stopped (nothing of the stack is left in the domain)."""
    from rabbit_msgs_py.node_runner import NodeStartError

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    started = []
    real = processes_module.NodeProcesses

    class Recorded(real):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            started.extend(self.procs.values())

    monkeypatch.setattr(processes_module, "NodeProcesses", Recorded)
    with pytest.raises(NodeStartError, match="sim_node: the viewer needs a display"):
        run_multi_process(StackConfig(duration=1.0, schedule=((0.0, 1.0),), viewer=True))
    assert [p.args[3] for p in started] == ["rabbit_policy.policy_node"]
    assert all(p.poll() is not None for p in started)

