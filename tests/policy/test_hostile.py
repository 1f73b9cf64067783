"""A stranger on the machine (issue 75), each attack provoked directly: the key run_stack
hands its node processes is on no command line and in no environment (another user reads
``/proc/PID/cmdline`` and, for the same user, ``environ``); a bare or replayed
``/hzd/gait_timing`` moves no keyed controller's timing."""

from __future__ import annotations

import os
import stat
import tempfile
import time
from pathlib import Path

import pytest
from std_msgs.msg import String

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.pairing import key_file, new_key, resolve_key, write_key_file
from rabbit_policy.bringup.config import StackConfig
from rabbit_policy.bringup.processes import NodeProcesses

from ros_helpers import GaitSigner, ros_context, spin_for, spin_until


@pytest.mark.unit
def test_a_key_file_is_owner_only_from_its_creation_and_refused_when_open_or_missing(tmp_path):
    key = new_key()
    path = write_key_file(tmp_path / "k", key)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and key_file(path).secret == key.encode()
    assert resolve_key("", file=str(path))[0].secret == key.encode()
    with pytest.raises(ValueError, match="not both"):
        resolve_key(key, file=str(path))
    path.chmod(0o640)
    with pytest.raises(ValueError, match="open to others"):
        key_file(path)
    with pytest.raises(ValueError, match="missing: No such file"):
        key_file(tmp_path / "missing")


@pytest.mark.ros
def test_run_stacks_node_processes_get_the_key_by_a_file_never_on_their_command_line_or_environment():
    config = StackConfig(duration=1.0, schedule=((0.0, 1.0),))
    scratch = tempfile.mkdtemp(prefix="rabbit_test_key_")  # 0700, as run_multi_process's
    key_path = os.path.join(scratch, "pairing_key")
    procs = NodeProcesses(config, log=open(os.devnull, "w"), hold=True, key_file=key_path)
    try:
        assert set(procs.procs) == {"sim_node", "hzd_controller_node", "policy_node"}
        for name, proc in procs.procs.items():
            cmdline = Path(f"/proc/{proc.pid}/cmdline").read_bytes().decode()
            environ = Path(f"/proc/{proc.pid}/environ").read_bytes().decode()
            assert config.pairing_key not in cmdline and config.pairing_key not in environ, name
            assert f"pairing_key_file:={key_path}" in cmdline, name
        assert stat.S_IMODE(os.stat(key_path).st_mode) == 0o600 and stat.S_IMODE(os.stat(scratch).st_mode) == 0o700
        assert key_file(Path(key_path)).secret == config.pairing_key.encode()
    finally:
        procs.stop()
        for entry in Path(scratch).iterdir():
            entry.unlink()
        os.rmdir(scratch)


@pytest.mark.ros
def test_a_keyed_controller_follows_only_its_paired_policys_signed_timing(capfd):
    """A bare ``at_once:7`` (the attack that took a lockstep run from RTF 8 to 0.15), one signed
    with another key, and a signed one from another policy instance of the same key (a replay)
    all leave the controller deciding as its policy says; the refusals are logged."""
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from std_msgs.msg import Float64MultiArray

    gait = GaitLibrary.load().nearest(1.0)
    signer, replay = GaitSigner(), GaitSigner(source="earlier_policy/11111111")
    with ros_context() as (context, executor):
        import rclpy

        controller = HZDControllerNode(context=context)  # started by hand: the user's key, as the signer's
        user = rclpy.create_node("timing_sender", context=context)
        for node in (controller, user):
            executor.add_node(node)
        alpha_pub = user.create_publisher(Float64MultiArray, topics.ALPHA, qos.GAIT_QOS)
        timing_pub = user.create_publisher(String, topics.GAIT_TIMING, qos.GAIT_QOS)
        timing_pub.publish(signer.announcement(20))
        alpha_pub.publish(signer.alpha(gait.alpha, gait.kd))
        assert spin_until(executor, lambda: controller.gait is not None)
        assert controller.sync.decision_period == 20
        timing_pub.publish(String(data="at_once:7"))
        spin_for(executor, 0.2)
        timing_pub.publish(replay.announcement(7))
        spin_for(executor, 0.3)
        assert controller.sync.decision_period == 20
    err = capfd.readouterr().err
    assert "rejected /hzd/gait_timing" in err and "not signed" in err


@pytest.mark.unit
def test_a_flood_of_unsigned_gaits_after_the_policys_first_loses_no_signed_gait():
    """3,000 unsigned gaits published right after the policy's signed first gait, all waiting
    before the controller takes any (a 10 kHz flood kept a stack from ever starting: the signed
    gait was pushed out of the reader, at depth 1 and at depth 1000, before it was taken): the
    controller still takes it."""
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from std_msgs.msg import Float64MultiArray

    gait = GaitLibrary.load().nearest(1.0)
    signer = GaitSigner()
    with ros_context() as (context, executor):
        import rclpy

        controller = HZDControllerNode(context=context)
        policy, stranger = (rclpy.create_node(name, context=context) for name in ("policy", "stranger"))
        timing_pub = policy.create_publisher(String, topics.GAIT_TIMING, qos.GAIT_QOS)
        alpha_pub = policy.create_publisher(Float64MultiArray, topics.ALPHA, qos.GAIT_QOS)
        forged_pub = stranger.create_publisher(Float64MultiArray, topics.ALPHA, qos.GAIT_QOS)
        for node in (controller, policy, stranger):
            executor.add_node(node)
        assert spin_until(executor, lambda: forged_pub.get_subscription_count() >= 1
                          and alpha_pub.get_subscription_count() >= 1)
        timing_pub.publish(signer.announcement(20))
        alpha_pub.publish(signer.alpha(gait.alpha, gait.kd))
        for _ in range(3000):  # nothing spins: every one waits in the controller's reader
            forged_pub.publish(Float64MultiArray(data=[0.0] * 24))
        time.sleep(1.0)  # delivered, not taken
        assert spin_until(executor, lambda: controller.gait is not None, timeout=3.0)
        assert controller.refused_gaits >= 1000


@pytest.mark.unit
def test_a_keyed_simulator_batches_on_no_strangers_decision_period():
    """The simulator ends a batch at each state its policy decides on; a bare ``at_once:7``
    (a stranger's) moves no batch of a keyed simulator, its policy's signed one does."""
    from rabbit_sim.sim_node import SimNode

    signer = GaitSigner()
    with ros_context() as (context, executor):
        import rclpy

        sim = SimNode(context=context, solo_check=0.0)  # started by hand: the user's key, as the signer's
        user = rclpy.create_node("timing_sender", context=context)
        for node in (sim, user):
            executor.add_node(node)
        timing_pub = user.create_publisher(String, topics.GAIT_TIMING, qos.GAIT_QOS)
        assert spin_until(executor, lambda: timing_pub.get_subscription_count() >= 1)
        period = lambda: getattr(sim._states.batcher._decisions, "period", None)  # noqa: E731 (ns, None: none)
        timing_pub.publish(String(data="at_once:7"))
        spin_for(executor, 0.3)
        assert period() is None
        timing_pub.publish(signer.announcement(20))
        assert spin_until(executor, lambda: period() == 20_000_000, timeout=3.0)


class Resetter:
    """A stranger's node that calls /sim/reset once, on the first state batch past 0.5 s of sim time."""

    def __init__(self, context) -> None:
        import rclpy
        from std_msgs.msg import Float64MultiArray
        from std_srvs.srv import Trigger

        self.node = rclpy.create_node("stranger", context=context)
        self._client = self.node.create_client(Trigger, topics.RESET_SERVICE, qos_profile=qos.SERVICE_QOS)
        self.node.create_subscription(Float64MultiArray, topics.STATE_BATCH, self._on_batch, qos.BATCH_QOS)
        self.called = False

    def _on_batch(self, msg) -> None:
        from std_srvs.srv import Trigger

        if not self.called and msg.data and msg.data[0] > 0.5e9:
            self.called = True
            self._client.call_async(Trigger.Request())

    def destroy_node(self) -> None:
        self.node.destroy_node()


@pytest.mark.ros
@pytest.mark.slow
def test_a_strangers_reset_mid_run_is_reported_and_the_run_is_not_complete():
    from rabbit_policy.bringup.in_process import run_in_process

    made = []

    def factory(context):
        made.append(Resetter(context))
        return made[-1].node

    config = StackConfig(duration=2.0, schedule=((0.0, 1.0),))
    report, _nodes = run_in_process(config, observers=[factory])
    assert made[0].called
    summary = report.summary()
    assert summary["completed"] is False and "was reset 1 time during the run" in summary["error"]


@pytest.mark.ros
def test_a_keyed_controller_takes_only_its_simulators_signed_mode_and_never_a_second_one(capfd):
    """/sim/mode steers decision_sync. A bare "realtime" (a stranger's) is refused; the mode
    the simulator signs with the key is taken; a later signed "realtime" is refused too, as
    a simulator's mode never changes while it runs: decision_sync stays on."""
    from rabbit_msgs_py.conversions import controller_id

    signer = GaitSigner()
    with ros_context() as (context, executor):
        import rclpy

        controller = HZDControllerNode(context=context)  # decision_sync not given: it follows /sim/mode
        user = rclpy.create_node("mode_sender", context=context)
        for node in (controller, user):
            executor.add_node(node)
        mode_pub = user.create_publisher(String, topics.SIM_MODE, qos.STATUS_QOS)
        mode_pub.publish(String(data="realtime"))
        spin_for(executor, 0.3)
        assert controller._sim_mode is None
        simulator = controller_id("sim_node")
        mode_pub.publish(String(data=signer.key.sign_settings(simulator, "lockstep")))
        assert spin_until(executor, lambda: controller._sim_mode == "lockstep")
        assert controller.sync.decision_sync
        mode_pub.publish(String(data=signer.key.sign_settings(simulator, "realtime")))
        spin_for(executor, 0.3)
        assert controller._sim_mode == "lockstep" and controller.sync.decision_sync
    err = capfd.readouterr().err
    assert "rejected /sim/mode 'realtime': the simulator's mode is not signed" in err
    assert "its mode does not change while it runs" in err


class BatchForger:
    """A stranger's node on /sim/state_batch: past 0.5 s of sim time it sends, once each, a
    forged unsigned row stamped 30 s (the attack that made run_stack report "stalled") and
    a signed batch of the run sent again after later ones (a replay)."""

    def __init__(self, context) -> None:
        import rclpy
        from std_msgs.msg import Float64MultiArray

        self.node = rclpy.create_node("batch_forger", context=context)
        self._pub = self.node.create_publisher(Float64MultiArray, topics.STATE_BATCH, qos.BATCH_QOS)
        self.node.create_subscription(Float64MultiArray, topics.STATE_BATCH, self._on_batch, qos.BATCH_QOS)
        self.first = None
        self.sent = False

    def _on_batch(self, msg) -> None:
        import array

        from rabbit_msgs_py.conversions import BATCH_FIELDS, state_batch_to_msg

        if self.first is None and msg.layout.dim[0].label.startswith("state signed="):
            self.first = msg
        if not self.sent and msg.data and msg.data[0] > 0.5e9:
            self.sent = True
            row = array.array("d", msg.data[:BATCH_FIELDS])
            row[0] = 30e9
            self._pub.publish(state_batch_to_msg(row, 1))
            self._pub.publish(self.first)

    def destroy_node(self) -> None:
        self.node.destroy_node()


@pytest.mark.ros
def test_a_forged_or_replayed_state_batch_moves_no_verdict_and_no_decision(capfd):
    from rabbit_policy.bringup.in_process import run_in_process

    made = []

    def factory(context):
        made.append(BatchForger(context))
        return made[-1].node

    config = StackConfig(duration=2.0, schedule=((0.0, 1.0),))
    report, nodes = run_in_process(config, observers=[factory])
    assert made[0].sent and made[0].first is not None
    summary = report.summary()
    assert summary["completed"] and not summary["stalled"] and not summary["fell"], summary.get("error")
    assert summary["duration"] == pytest.approx(2.0)
    assert nodes["supervisor"]._batches.refused == nodes["policy_node"]._batches.refused == 2  # the forgery, the replay
    assert nodes["policy_node"].decisions_given_up == 0
    assert "the state batch is not signed" in capfd.readouterr().err  # (the replay's line: throttled, 1 a second)


@pytest.mark.ros
def test_a_state_batch_flood_wakes_no_supervisor_callback_and_loses_no_real_batch():
    """The supervisor takes ``/sim/state_batch`` in bulk (``rabbit_msgs_py.polled``): the topic
    is on no subscription of its node (no executor callback a message, however many come), and
    a burst of 1,500 malformed batches around a real (signed) one, taken together, leaves the
    real state taken and every other refused and counted."""
    import array
    import math

    import rclpy
    from std_msgs.msg import Float64MultiArray

    from rabbit_msgs_py.conversions import state_batch_to_msg
    from rabbit_msgs_py.pairing import PairingKey
    from rabbit_policy.bringup.supervisor import BATCH_TAKE_QOS, Supervisor

    text = new_key()
    with ros_context() as (context, executor):
        supervisor = Supervisor(StackConfig(duration=10.0, schedule=((0.0, 1.0),), pairing_key=text), context=context)
        assert supervisor.resolve_topic_name(topics.STATE_BATCH) not in {s.topic_name for s in supervisor.subscriptions}
        flooder = rclpy.create_node("flooder", context=context)
        executor.add_node(supervisor)
        executor.add_node(flooder)
        publisher = flooder.create_publisher(Float64MultiArray, topics.STATE_BATCH, BATCH_TAKE_QOS)
        assert spin_until(executor, lambda: publisher.get_subscription_count() == 1)
        flood = Float64MultiArray(data=[math.nan] * 30)
        row = array.array("d", [5_000_000, 0.25] + [0.0] * 20)
        real = state_batch_to_msg(row, 1, PairingKey.parse(text).batch_label("sim_node/a", 1, row.tobytes()))
        for message in [flood] * 750 + [real] + [flood] * 750:
            publisher.publish(message)
        assert spin_until(executor, lambda: supervisor._rejections.counts.get("state_batch", 0) == 1500)
        assert supervisor.sim_stamp == 5_000_000 and supervisor._start == (5_000_000, 0.25)


@pytest.mark.ros
def test_bench_stacks_flooder_stops_on_sigterm_when_started_in_the_background():
    """A process started in the background inherits SIGINT ignored (a nohup'd bench_stack's
    flood scenarios left their flooders running so): the flooder stops on SIGTERM, whatever
    SIGINT is, and says what it sent."""
    import json
    import signal
    import subprocess
    import sys

    flooder = subprocess.Popen([sys.executable, "-m", "rabbit_policy.commands.bench_stack", "--flooder"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        assert "until SIGTERM" in flooder.stderr.readline()  # publishing
        flooder.send_signal(signal.SIGINT)  # ignored, as in a background job
        flooder.terminate()
        out = flooder.communicate(timeout=60)[0]
    finally:
        flooder.kill()
    assert flooder.returncode == 0 and set(json.loads(out.strip().splitlines()[-1])) == {"sent", "per_s"}


@pytest.mark.ros
@pytest.mark.slow
def test_forged_joint_states_are_refused_by_the_keyed_controller_and_the_walk_completes(capfd):
    """A stranger's /joint_states (finite values, a stamp 1000 s ahead: before states were
    signed, three of them made the controller wait for a decision that never came, and the
    run was not complete): the simulator signs its states, a keyed controller takes no other."""
    import rclpy
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    from rabbit_msgs_py.conversions import stamp_from_ns, stamp_to_ns
    from rabbit_msgs_py.joints import JOINT_NAMES
    from rabbit_policy.bringup.in_process import run_in_process

    def forger(context):
        node = rclpy.create_node("forger", context=context)
        publisher = node.create_publisher(JointState, topics.JOINT_STATES, qos.STREAM_QOS)
        forged = JointState(name=list(JOINT_NAMES), position=[0.0, 0.75, 0.1, 0.2, 0.3, 0.2, 0.3],
                            velocity=[1.0] + [0.0] * 6)
        forged.header.stamp = stamp_from_ns(1000 * 10 ** 9)

        def on_clock(msg: Clock) -> None:
            if stamp_to_ns(msg.clock) == 10 ** 9:  # at t = 1 s of sim time
                for _ in range(3):
                    publisher.publish(forged)
        node.create_subscription(Clock, topics.CLOCK, on_clock, qos.CLOCK_QOS)
        return node

    report, nodes = run_in_process(StackConfig(duration=3.0, schedule=((0.0, 1.0),)), observers=[forger])
    assert report.completed and not report.fell and report.decisions_lost == 0
    assert nodes["hzd_controller_node"].rejected_states >= 1
    assert "not signed with this stack's pairing key" in capfd.readouterr().err


class StateReplayer:
    """A stranger's node on /joint_states: it keeps the signed state of t = 0.5 s and, when
    /clock says 1 s, sends it again three times (before states were ordered, the controller
    took it for a reset: it restarted its walk, waited out a decision and the run was not
    complete). It also records each state's stamp, positions and velocities as it arrives."""

    def __init__(self, context) -> None:
        import rclpy
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState

        self.node = rclpy.create_node("state_replayer", context=context)
        self._pub = self.node.create_publisher(JointState, topics.JOINT_STATES, qos.STREAM_QOS)
        self.node.create_subscription(JointState, topics.JOINT_STATES, self._on_state, qos.STREAM_QOS)
        self.node.create_subscription(Clock, topics.CLOCK, self._on_clock, qos.CLOCK_QOS)
        self.kept, self.sent, self.rows = None, False, []

    def _on_state(self, msg) -> None:
        from rabbit_msgs_py.conversions import stamp_to_ns

        stamp = stamp_to_ns(msg.header.stamp)
        self.rows.append((stamp, *msg.position, *msg.velocity))
        if stamp == 500_000_000 and self.kept is None:
            self.kept = msg

    def _on_clock(self, msg) -> None:
        from rabbit_msgs_py.conversions import stamp_to_ns

        if stamp_to_ns(msg.clock) == 10 ** 9 and self.kept is not None and not self.sent:
            self.sent = True
            for _ in range(3):
                self._pub.publish(self.kept)

    def destroy_node(self) -> None:
        self.node.destroy_node()


@pytest.mark.ros
@pytest.mark.slow
def test_a_replayed_signed_state_is_refused_and_the_walk_is_the_ros_free_loops_bit_for_bit(capfd):
    """The simulator signs each state with its placement count; a keyed controller takes them
    in (placement, stamp) order, so a signed state sent again after later ones moves nothing:
    the walk completes with no decision lost, its states those of the ROS-free loop."""
    import numpy as np

    from rabbit_policy.bringup.in_process import run_in_process
    from stack_helpers import loop_states

    made = []

    def factory(context):
        made.append(StateReplayer(context))
        return made[-1].node

    report, nodes = run_in_process(StackConfig(duration=2.0, schedule=((0.0, 1.0),)), observers=[factory])
    assert made[0].sent and report.completed and not report.fell and report.decisions_lost == 0
    assert nodes["hzd_controller_node"].rejected_states == 3
    walked, newest = [], -1
    for stamp, *row in made[0].rows:  # the simulator's states: in stamp order (a re-send or the replays left out)
        if stamp > newest:
            walked.append(row)
            newest = stamp
    assert np.array_equal(np.array(walked), loop_states(2.0))
    assert "(a replay)" in capfd.readouterr().err
