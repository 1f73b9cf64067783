"""Nobody takes or disturbs the robot (docs/faults.md). Explicit pairing: with the stack's
pairing key no other node's torques are ever applied, whatever happens to the real
controller or the policy, and silence never hands the robot to another node; a controller
the stack restarts with the key resumes at once. One stack per namespace: a second
simulator, controller or policy refuses to start and the running robot walks on exactly as
the ROS-free loop does.

Each node lives in a ROS context of its own, standing in for its process: "killed" is its
context shut down, "stopped" is its executor not spun (SIGSTOP). The rogue answers every
state with its exact stamp, 37 N m on each joint, under a name of its own or copying the
real controller's last ``frame_id`` (signature included); it runs from before the stack
starts or from mid-run. Every applied effort is watched on ``/joint_states``."""

from __future__ import annotations

import pytest
from sensor_msgs.msg import JointState

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.conversions import torques_to_msg
from rabbit_msgs_py.pairing import new_key
from rabbit_msgs_py.solo import PROCESS_SOLO_CHECK
from rabbit_policy.policy_node import PolicyNode
from rabbit_sim.sim_node import SimNode

from ros_helpers import ros_context, spin_for, spin_until, wait_until as wait_for

pytestmark = [pytest.mark.ros, pytest.mark.slow]

ROGUE_TORQUE = 37.0


class Rogue:
    """A node on ``/joint_torques`` that answers each state at once with 37 N m: under its
    own id (``echo``) or under the real controller's last frame_id (``copy``)."""

    def __init__(self, context, kind: str) -> None:
        import rclpy

        self.node = rclpy.create_node("rogue", context=context)
        self.kind, self.frame_id, self.sent = kind, "rogue/0000", 0
        self._pub = self.node.create_publisher(JointState, topics.JOINT_TORQUES, qos.STREAM_QOS)
        self.node.create_subscription(JointState, topics.JOINT_STATES, self._on_state, qos.STREAM_QOS)
        if kind == "copy":
            self.node.create_subscription(JointState, topics.JOINT_TORQUES, self._on_reply, qos.STREAM_QOS)

    def _on_reply(self, msg: JointState) -> None:
        if "rogue" not in msg.header.frame_id:
            self.frame_id = msg.header.frame_id

    def _on_state(self, msg: JointState) -> None:
        self._pub.publish(torques_to_msg([ROGUE_TORQUE] * 4, msg.header.stamp, self.frame_id))
        self.sent += 1


def _watch(context, executor) -> list:
    import rclpy

    efforts: list = []
    watcher = rclpy.create_node("effort_watcher", context=context)
    watcher.create_subscription(JointState, topics.JOINT_STATES, lambda m: efforts.append(list(m.effort[3:])),
                                qos.STREAM_QOS)
    executor.add_node(watcher)
    return efforts


@pytest.mark.parametrize("rogue_from, rogue_kind", [("start", "echo"), ("mid-run", "copy")])
@pytest.mark.parametrize("fault", ["policy killed", "controller stopped", "controller killed"])
def test_no_other_node_ever_gets_the_robot_with_the_stacks_key(fault, rogue_from, rogue_kind):
    key = new_key()
    with ros_context() as (ctx_s, ex_s), ros_context() as (ctx_p, ex_p), ros_context() as (ctx_c, ex_c), \
            ros_context() as (ctx_r, ex_r):
        rogue = Rogue(ctx_r, rogue_kind)
        if rogue_from == "start":
            ex_r.add_node(rogue.node)
        efforts = _watch(ctx_s, ex_s)
        sim = SimNode(context=ctx_s, pairing_key=key, resend_timeout=0.05)
        ex_s.add_node(sim)
        ex_p.add_node(PolicyNode(context=ctx_p, pairing_key=key))
        controller = HZDControllerNode(context=ctx_c, pairing_key=key, decision_sync=True, decision_timeout=0.5)
        ex_c.add_node(controller)
        everyone = [ex_s, ex_p, ex_c, ex_r]
        assert spin_until(everyone, lambda: sim.time >= 0.3, timeout=60.0), f"stuck at {sim.time}"
        if rogue_from == "mid-run":
            ex_r.add_node(rogue.node)
            spin_until(everyone, lambda: rogue.sent > 20, timeout=10.0)
        t_fault = sim.time
        if fault == "policy killed":  # the controller holds its due reply for decision_timeout, then answers
            ctx_p.try_shutdown()
            assert spin_until([ex_s, ex_c, ex_r], lambda: sim.time >= t_fault + 0.3, timeout=60.0)
        elif fault == "controller stopped":  # SIGSTOP for 1.5 s (longer than the old 1 s takeover)
            spin_for([ex_s, ex_p, ex_r], 1.5)
            assert sim.time <= t_fault + 0.002  # held (a reply in flight may land)
            assert spin_until(everyone, lambda: sim.time >= t_fault + 0.3, timeout=60.0)  # then resumed
        else:  # killed: the robot waits for a controller the stack starts with its key
            ctx_c.try_shutdown()
            spin_for([ex_s, ex_p, ex_r], 1.5)
            assert sim.time <= t_fault + 0.002
        assert rogue.sent > 20  # the rogue answered many states...
        assert sim.torques_rejected > 0  # ...and was refused
        assert not sim.fallen
        assert efforts and all(abs(e - ROGUE_TORQUE) > 1e-9 for row in efforts for e in row)


def test_nodes_started_by_hand_pair_by_the_users_key_and_a_rogue_copying_the_controller_moves_nothing():
    """The three nodes started as ``ros2 run`` starts them, no ``pairing_key`` given: the
    simulator and the controller pair by the user's key file (``$ROS_HOME``, the test's own), made
    on first use. A rogue without the file copies the controller's ``frame_id`` onto
    ``/joint_torques`` and answers every state: none of its torques is applied. (Before keys by
    default, such a rogue had its 37 N m applied on a third of the states and RABBIT fell.)"""
    import os
    from pathlib import Path

    with ros_context() as (ctx_s, ex_s), ros_context() as (ctx_p, ex_p), ros_context() as (ctx_c, ex_c), \
            ros_context() as (ctx_r, ex_r):
        rogue = Rogue(ctx_r, "copy")
        ex_r.add_node(rogue.node)
        efforts = _watch(ctx_s, ex_s)
        sim = SimNode(context=ctx_s)
        ex_s.add_node(sim)
        ex_p.add_node(PolicyNode(context=ctx_p))
        controller = HZDControllerNode(context=ctx_c)
        ex_c.add_node(controller)
        everyone = [ex_s, ex_p, ex_c, ex_r]
        assert spin_until(everyone, lambda: sim.time >= 1.0 and rogue.sent > 50, timeout=90.0), f"at {sim.time}"
        assert not sim.fallen  # (its replies are refused, or come after the state was answered: never applied)
        assert "#" in rogue.frame_id  # it copied the controller's signed id
        assert efforts and all(abs(e - ROGUE_TORQUE) > 1e-9 for row in efforts for e in row)
    key_file = Path(os.environ["ROS_HOME"]) / "rabbit_hzd" / "pairing_key"
    assert key_file.stat().st_mode & 0o077 == 0


def test_a_rogue_publisher_does_not_keep_the_real_nodes_from_starting():
    """A rogue publishes on ``/joint_torques`` (answering every state) and a test tool holds a
    publisher of ``/hzd/alpha`` open before the stack starts: the controller (with the
    stack's key) and the policy, looking as processes started by hand do (``solo_check``),
    start all the same (the solo check once counted any publisher of those topics as another
    of their kind, and the robot was held for good), the robot walks, and the rogue's torques
    stay refused. (The tool publishes nothing: gaits are not signed, docs/faults.md.)"""
    import rclpy
    from std_msgs.msg import Float64MultiArray

    key = new_key()
    with ros_context() as (context, executor), ros_context() as (ctx_r, ex_r):
        rogue = Rogue(ctx_r, "echo")
        alpha = rclpy.create_node("gait_tool", context=ctx_r)
        alpha.create_publisher(Float64MultiArray, topics.ALPHA, qos.GAIT_QOS)
        ex_r.add_node(rogue.node)
        ex_r.add_node(alpha)
        spin_for(ex_r, 0.5)
        efforts = _watch(context, executor)
        sim = SimNode(context=context, pairing_key=key)
        policy = PolicyNode(context=context, solo_check=0.5, pairing_key=key)
        controller = HZDControllerNode(context=context, pairing_key=key, solo_check=0.5)
        for node in (sim, policy, controller):
            executor.add_node(node)
        assert spin_until((executor, ex_r), lambda: sim.time >= 0.5, timeout=60.0), f"stuck at {sim.time}"
        assert controller.solo.started and policy.solo.started
        assert not controller.solo.refused and not policy.solo.refused
        assert rogue.sent > 20 and sim.torques_rejected > 0 and not sim.fallen
        assert efforts and all(abs(e - ROGUE_TORQUE) > 1e-9 for row in efforts for e in row)


def _stuck(sim: SimNode, controller: HZDControllerNode) -> str:
    """Where a lockstep walk that stopped stands: what each side received and sent."""
    return (f"stuck at t = {sim.time:.3f} s; simulator: paired {sim.controller}, torques received "
            f"{sim.torques_received}, refused {sim.torques_rejected}, states sent {sim.states_published}, re-sends "
            f"{sim.resends}; controller {controller.source}: states received {controller.states_received}, "
            f"missing {controller.sync.missing}, {controller.statistics()}")


def test_a_controller_the_stack_restarts_with_its_key_is_paired_and_answers_at_once():
    """The controller is killed mid-walk, a rogue answering every state meanwhile; the stack
    starts a new instance with the key: the simulator pairs with it (logged), and it answers
    the state waiting for it at once instead of waiting out decision_timeout for a decision
    the policy gave the old instance."""
    key = new_key()
    with ros_context() as (context, executor), ros_context() as (ctx_r, ex_r):
        efforts = _watch(context, executor)
        sim = SimNode(context=context, pairing_key=key, resend_timeout=0.05)
        executor.add_node(sim)
        executor.add_node(PolicyNode(context=context, pairing_key=key))
        rogue = Rogue(ctx_r, "echo")
        ex_r.add_node(rogue.node)
        with ros_context() as (ctx_a, ex_a):
            old = HZDControllerNode(context=ctx_a, pairing_key=key, decision_sync=True)
            ex_a.add_node(old)
            assert spin_until((executor, ex_a, ex_r), lambda: sim.time >= 0.3, timeout=60.0), _stuck(sim, old)
        spin_for((executor, ex_r), 0.3)
        t_stopped = sim.time
        assert sim.controller == old.source
        with ros_context() as (ctx_b, ex_b):
            new = HZDControllerNode(context=ctx_b, pairing_key=key, decision_sync=True, decision_timeout=30.0)
            ex_b.add_node(new)
            assert spin_until((executor, ex_b, ex_r), lambda: sim.time >= t_stopped + 0.1, timeout=60.0), \
                _stuck(sim, new)
            assert sim.controller == new.source
            assert new.decisions_timed_out == 0  # (with a 30 s timeout, a wait would have stalled the test)
            assert new.decisions_waited > 0  # it follows the policy's decisions again
        assert not sim.fallen
        assert all(abs(e - ROGUE_TORQUE) > 1e-9 for row in efforts for e in row)


def test_the_pairing_key_cannot_be_read_back_from_the_nodes():
    key = new_key()
    with ros_context() as (context, executor):
        for node in (SimNode(context=context, pairing_key=key), HZDControllerNode(context=context, pairing_key=key),
                     PolicyNode(context=context, pairing_key=key)):
            executor.add_node(node)
            assert not node.has_parameter("pairing_key")
            assert key not in repr(getattr(node, "settings", "")) and key not in repr(getattr(node, "config", ""))


def test_a_bad_pairing_key_stops_the_node_with_one_line():
    from rabbit_msgs_py.node_runner import NodeStartError

    with ros_context() as (context, _executor):
        for cls in (SimNode, HZDControllerNode):
            with pytest.raises(NodeStartError, match="pairing_key must be 16 to 64 characters"):
                cls(context=context, pairing_key="tooshort")


@pytest.mark.parametrize("kind", ["simulator", "controller", "policy"])
def test_a_second_node_of_a_kind_refuses_to_start_and_the_running_robot_is_not_disturbed(kind):
    """While a stack walks (run_in_process, lockstep, its states recorded), a second node of
    one kind comes and goes three times in the same namespace, each in a context of its own,
    looking as a process started by hand does (``solo_check``): each refuses, having
    published nothing, and the stack's states are the ROS-free loop's bit for bit.

    The stack walks until the third intruder is gone (then it is stopped), however fast
    this machine runs it: a fixed 6 s walk ended before the second intruder had finished
    looking on a fast one (CI, 2026-11-27)."""
    import threading

    import numpy as np

    from rabbit_policy.bringup.config import StackConfig

    from rabbit_policy.bringup.in_process import run_in_process
    from rabbit_policy.experiment.loop import ClosedLoop
    from rabbit_policy.experiment.scenario import Scenario
    from rabbit_policy.spec.make import make_policy

    node_class = {"simulator": SimNode, "controller": HZDControllerNode, "policy": PolicyNode}[kind]
    states: list = []

    def recorder(context):
        import rclpy

        node = rclpy.create_node("trajectory_recorder", context=context)
        node.create_subscription(JointState, topics.JOINT_STATES,
                                 lambda m: states.append(list(m.position) + list(m.velocity)), qos.STREAM_QOS)
        return node

    intruders_done = threading.Event()
    result: dict = {}
    run = threading.Thread(target=lambda: result.update(run=run_in_process(
        StackConfig(duration=600.0, schedule=((0.0, 1.0),)), observers=[recorder], stop=intruders_done.is_set)))
    run.start()
    try:
        refusals = []
        assert wait_for(lambda: len(states) > 100 or not run.is_alive(), 60.0), "the stack did not start"
        while len(refusals) < 3 and run.is_alive():
            with ros_context() as (context, executor):
                intruder = node_class(context=context, solo_check=PROCESS_SOLO_CHECK)
                executor.add_node(intruder)
                spin_until(executor, lambda: getattr(intruder, "done", False) or intruder.solo.started,
                           timeout=PROCESS_SOLO_CHECK + 5.0)
                refusals.append((intruder.solo.refused, intruder.solo.started, run.is_alive()))
    finally:
        intruders_done.set()
        run.join(timeout=300)
    report, _nodes = result["run"]
    assert report.error == "interrupted" and not report.fell, report  # walking until stopped
    assert len(refusals) == 3 and all(found and not started and alive for found, started, alive in refusals), refusals
    unique = np.array([row for i, row in enumerate(states) if i == 0 or row != states[i - 1]])
    loop = ClosedLoop(Scenario.constant(1.0), make_policy("classic"))
    reference = [loop.data.qpos.tolist() + loop.data.qvel.tolist()]
    for _ in range(len(unique) - 1):
        loop.tick()
        reference.append(loop.data.qpos.tolist() + loop.data.qvel.tolist())
    assert np.array_equal(unique, np.array(reference))


def test_a_node_started_by_hand_beside_a_stack_exits_with_one_line():
    """``python -m rabbit_sim.sim_node`` (as ``ros2 run`` starts it, with solo_check) in the
    namespace of a running simulator: exit 1, one error line naming what it found."""
    import subprocess
    import sys

    with ros_context() as (context, executor):
        running = SimNode(context=context)
        executor.add_node(running)
        spin_for(executor, 0.2)
        proc = subprocess.Popen([sys.executable, "-m", "rabbit_sim.sim_node"], stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
        while proc.poll() is None:
            spin_for(executor, 0.1)
        out = proc.stdout.read()
    assert proc.returncode == 1, out
    errors = [line for line in out.splitlines() if "ERROR" in line or line.startswith("error:")]
    assert len(errors) == 1 and "another simulator runs in namespace /" in errors[0], out
    assert "Traceback" not in out
