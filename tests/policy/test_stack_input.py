"""What the ROS 2 node stack takes in: speed commands (/cmd_speed, /cmd_vel), gaits (signed
with a key, malformed), pushes on /push, bursts of bad input, and a memory or body-state
policy's inputs: rejected with a logged line, the last good state kept."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, Header, String

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.conversions import alpha_to_msg
from rabbit_msgs_py.pairing import new_key
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.policy_node import PolicyNode

from ros_helpers import BatchSigner, ros_context, spin_for, spin_until
from stack_helpers import context_node, residual_policy_file, start_stack

pytestmark = pytest.mark.ros


def test_bad_speed_commands_are_clamped_or_rejected():
    with ros_context() as (context, executor):
        policy = PolicyNode(context=context)
        executor.add_node(policy)
        import rclpy

        user = rclpy.create_node("user", context=context)
        executor.add_node(user)
        pub = user.create_publisher(Float64, topics.CMD_SPEED, qos.COMMAND_QOS)
        assert spin_until(executor, lambda: pub.get_subscription_count() > 0)
        pub.publish(Float64(data=1.2))
        assert spin_until(executor, lambda: policy.desired_speed == 1.2)
        for bad in (math.nan, math.inf, -math.inf):
            pub.publish(Float64(data=bad))
        assert spin_until(executor, lambda: policy.rejected_commands == 3)
        assert policy.desired_speed == 1.2
        pub.publish(Float64(data=3.0))
        assert spin_until(executor, lambda: policy.desired_speed == 1.5)
        pub.publish(Float64(data=0.1))
        assert spin_until(executor, lambda: policy.desired_speed == 0.7)


def test_the_classic_speed_integral_is_a_policy_node_parameter_and_refused_for_the_learned_one():
    from rabbit_msgs_py.node_runner import NodeStartError

    with ros_context() as (context, _executor):
        node = PolicyNode(context=context, speed_integral=0.3)
        assert node.policy.name == "classic/interpolate+integral0.3@20ticks"
        assert node.get_parameter("speed_integral").value == 0.3
        node.destroy_node()
        with pytest.raises(NodeStartError, match="classic controller's") as error:
            PolicyNode(context=context, policy="learned", speed_integral=0.3)
        assert "\n" not in str(error.value)
        with pytest.raises(NodeStartError, match="speed_integral"):
            PolicyNode(context=context, speed_integral=math.nan)


def test_cmd_vel_commands_the_speed_as_teleop_tools_send_it(capfd):
    """geometry_msgs/Twist on /cmd_vel (teleop_twist_keyboard, navigation): linear.x is the
    commanded speed, through the same clamping and rejection as /cmd_speed; a turn or any
    other field is ignored with one warning."""
    from geometry_msgs.msg import Twist

    with ros_context() as (context, executor):
        policy = PolicyNode(context=context)
        executor.add_node(policy)
        import rclpy

        user = rclpy.create_node("teleop", context=context)
        executor.add_node(user)
        pub = user.create_publisher(Twist, topics.CMD_VEL, qos.COMMAND_QOS)
        assert spin_until(executor, lambda: pub.get_subscription_count() > 0)
        for _ in range(2):
            msg = Twist()
            msg.linear.x, msg.angular.z = 1.1, 0.5
            pub.publish(msg)
        assert spin_until(executor, lambda: policy.desired_speed == 1.1)
        msg = Twist()
        msg.linear.x = math.nan
        pub.publish(msg)
        assert spin_until(executor, lambda: policy.rejected_commands == 1) and policy.desired_speed == 1.1
        msg.linear.x = 9.0
        pub.publish(msg)
        assert spin_until(executor, lambda: policy.desired_speed == 1.5)
    assert capfd.readouterr().err.count("only linear.x (the speed) is used") == 1


def test_malformed_gaits_are_rejected_and_the_last_good_one_kept(capfd):
    """Without a pairing key (``pairing_key:=none``, gaits as anyone sends them): every
    malformed alpha and Kd is rejected, the last good gait kept. (With the user's key, as nodes
    started by hand have it, see the next test.)"""
    gait = GaitLibrary.load().nearest(1.0)
    with ros_context() as (context, executor):
        import rclpy

        controller = HZDControllerNode(context=context, pairing_key="none")
        user = rclpy.create_node("gait_sender", context=context)
        for node in (controller, user):
            executor.add_node(node)
        alpha_pub = user.create_publisher(Float64MultiArray, topics.ALPHA, qos.GAIT_QOS)
        kd_pub = user.create_publisher(Float64, topics.KD, qos.GAIT_QOS)
        alpha_pub.publish(alpha_to_msg(gait.alpha))
        kd_pub.publish(Float64(data=gait.kd))
        assert spin_until(executor, lambda: controller.gait is not None)
        good = controller.gait

        wrong_size = Float64MultiArray(data=[0.1] * 23)
        nan_alpha = alpha_to_msg(gait.alpha)
        nan_alpha.data[3] = math.nan
        out_of_bounds = alpha_to_msg([a + 3.0 for a in gait.alpha])
        swapped = alpha_to_msg(gait.alpha)
        swapped.layout.dim = list(reversed(swapped.layout.dim))
        for bad in (wrong_size, nan_alpha, out_of_bounds, swapped):
            alpha_pub.publish(bad)
            spin_for(executor, 0.05)
        for bad_kd in (math.nan, -1.0, 1e6, 0.0):  # (0.0 was taken silently: no damping at all)
            kd_pub.publish(Float64(data=bad_kd))
            spin_for(executor, 0.05)
        assert spin_until(executor, lambda: controller.rejected_gaits == 8)
        assert controller.gait == good
        huge = alpha_to_msg(gait.alpha)
        huge.data = [1e308] * 24
        alpha_pub.publish(huge)
        assert spin_until(executor, lambda: controller.rejected_gaits == 9)
    logged = [line for line in capfd.readouterr().err.splitlines() if "rejected /hzd/alpha" in line]
    assert 1 <= len(logged) <= 5 and all(len(line) < 300 for line in logged)  # at most one a second (below)


def test_with_a_key_only_the_paired_policys_signed_gaits_are_taken_in_order(capfd):
    """The controller started by hand (the user's key): a gait signed with the key is taken,
    its Kd from its signature (``/hzd/kd`` alone moves nothing); an unsigned gait, one signed
    with another key, one whose coefficients changed after signing, and a copy of a signed gait
    sent again after a later one are refused, logged, and never counted as a decision's part, as
    are gaits of another policy instance with the same key while this one is alive."""
    from rabbit_msgs_py.pairing import PairingKey

    from ros_helpers import GaitSigner

    library = GaitLibrary.load()
    slow, fast = library.nearest(0.8), library.nearest(1.2)
    signer = GaitSigner()
    with ros_context() as (context, executor):
        import rclpy

        controller = HZDControllerNode(context=context)
        user = rclpy.create_node("gait_sender", context=context)
        for node in (controller, user):
            executor.add_node(node)
        alpha_pub = user.create_publisher(Float64MultiArray, topics.ALPHA, qos.GAIT_QOS)
        kd_pub = user.create_publisher(Float64, topics.KD, qos.GAIT_QOS)
        timing_pub = user.create_publisher(String, topics.GAIT_TIMING, qos.GAIT_QOS)
        first = signer.alpha(slow.alpha, slow.kd)
        alpha_pub.publish(first)  # before its policy's signed settings: held, neither taken nor refused
        spin_for(executor, 0.2)
        assert controller.gait is None and controller.refused_gaits == 0
        timing_pub.publish(signer.announcement())
        assert spin_until(executor, lambda: controller.gait is not None)
        assert controller.gait == (list(slow.alpha), slow.kd)
        kd_pub.publish(Float64(data=77.0))  # unsigned Kd: for observers only
        other = PairingKey.parse(new_key())
        tampered = signer.alpha(fast.alpha, fast.kd)
        tampered.data[0] += 0.01
        for bad in (alpha_to_msg(fast.alpha),
                    alpha_to_msg(fast.alpha, other.gait_signature("rogue/1", 99, list(fast.alpha), fast.kd)),
                    tampered, first):  # (first: a copy of gait 1, after gait 2 was signed)
            alpha_pub.publish(bad)
            spin_for(executor, 0.05)
        assert spin_until(executor, lambda: controller.refused_gaits == 4)
        assert controller.gait == (list(slow.alpha), slow.kd) and controller.rejected_gaits == 0
        alpha_pub.publish(signer.alpha(fast.alpha, fast.kd))
        assert spin_until(executor, lambda: controller.gait == (list(fast.alpha), fast.kd))
        # another policy instance with the same key (a replayed bag's gaits): refused while this one is alive,
        # taken once it has been silent for a second (a restarted policy)
        replay = GaitSigner(source="earlier_policy/11111111")
        alpha_pub.publish(replay.alpha(slow.alpha, slow.kd))
        assert spin_until(executor, lambda: controller.refused_gaits == 5)
        assert controller.gait == (list(fast.alpha), fast.kd)
        spin_for(executor, 1.2)
        timing_pub.publish(replay.announcement())
        alpha_pub.publish(replay.alpha(slow.alpha, slow.kd))
        assert spin_until(executor, lambda: controller.gait == (list(slow.alpha), slow.kd))
    refused = [line for line in capfd.readouterr().err.splitlines() if "refused a gait on /hzd/alpha" in line]
    assert 1 <= len(refused) <= 3 and "moves nothing" in refused[0]


def test_a_burst_of_bad_input_is_counted_in_full_and_logged_at_most_once_a_second(capfd):
    """10,000-message bursts (issue 39: 848 error lines and a 0.2 s lockstep stall for 10k bad
    Kd): every rejection that arrives (the subscriptions' depth drops the rest, as QoS says)
    is counted, and each kind (bad Kd, bad alpha, a speed clamped, a speed rejected) logs at
    most one line per wall second, saying how many it did not log."""
    gait = GaitLibrary.load().nearest(1.0)
    burst = 1000
    with ros_context() as (context, executor):
        import rclpy

        controller = HZDControllerNode(context=context, pairing_key="none")  # unsigned gaits are validated
        policy = PolicyNode(context=context)
        user = rclpy.create_node("flooder", context=context)
        for node in (controller, policy, user):
            executor.add_node(node)
        def deep(profile):  # the nodes' QoS, with room for the whole burst
            return rclpy.qos.QoSProfile(depth=burst + 10, reliability=profile.reliability,
                                        durability=profile.durability)
        kd_pub = user.create_publisher(Float64, topics.KD, deep(qos.GAIT_QOS))
        alpha_pub = user.create_publisher(Float64MultiArray, topics.ALPHA, deep(qos.GAIT_QOS))
        speed_pub = user.create_publisher(Float64, topics.CMD_SPEED, deep(qos.COMMAND_QOS))
        assert spin_until(executor, lambda: kd_pub.get_subscription_count() and speed_pub.get_subscription_count()
                          and alpha_pub.get_subscription_count())
        capfd.readouterr()
        start = time.monotonic()
        bad_alpha = alpha_to_msg([a + 3.0 for a in gait.alpha])
        for i in range(burst):  # the gait topics keep one message (depth 1): let each be taken
            kd_pub.publish(Float64(data=-1.0))
            alpha_pub.publish(bad_alpha)
            speed_pub.publish(Float64(data=math.nan if i % 2 else 9.0))
            for _ in range(3):
                executor.spin_once(timeout_sec=0.0)
        # what the nodes' subscription depth let through, until nothing more comes for 1 s
        seen, quiet_since = (-1, -1), time.monotonic()
        while time.monotonic() - quiet_since < 1.0 and time.monotonic() - start < 120:
            spin_for(executor, 0.1)
            now_seen = (controller.rejected_gaits, policy.rejected_commands)
            if now_seen != seen:
                seen, quiet_since = now_seen, time.monotonic()
        elapsed = time.monotonic() - start
        assert controller.rejected_gaits >= 100 and policy.rejected_commands >= 100, seen
        spin_for(executor, 2.5)  # the nodes' 1 s timers say the tail of the burst
    err = capfd.readouterr().err.splitlines()
    allowed = 1 + math.ceil(elapsed)  # one line at once, then one per second of the burst
    for pattern in ("rejected /hzd/kd", "rejected /hzd/alpha", "rejected /cmd_speed", "/cmd_speed 9"):
        lines = [line for line in err if pattern in line]
        assert 1 <= len(lines) <= allowed, (pattern, len(lines), allowed)
    for kind in ("kd", "alpha", "reject /cmd_speed", "clamp /cmd_speed"):  # the unlogged ones are said, counted
        assert any(f"more of kind '{kind}'" in line
                   for line in err if kind.split()[-1].strip("/") in line), kind


@pytest.mark.slow
def test_push_topic_applies_good_wrenches_and_rejects_bad_ones():
    from geometry_msgs.msg import Wrench

    with ros_context() as (context, executor):
        import rclpy

        nodes = start_stack(context, executor)
        sim = nodes["sim"]
        assert spin_until(executor, lambda: sim.time >= 0.5)
        pusher = rclpy.create_node("pusher", context=context)
        executor.add_node(pusher)
        publisher = pusher.create_publisher(Wrench, topics.PUSH, qos.COMMAND_QOS)
        bad, good = Wrench(), Wrench()
        bad.force.x = float("nan")
        good.force.x = -40.0
        publisher.publish(bad)
        publisher.publish(good)
        assert spin_until(executor, lambda: sim.pushes_applied == 1 and sim.pushes_rejected == 1)
        t = sim.time
        assert spin_until(executor, lambda: sim.time >= t + 1.0)
        assert not sim.fallen  # a small push: the robot walks on


def test_policy_node_starts_a_memory_policy_afresh_when_the_robot_is_placed_again(tmp_path):
    from std_msgs.msg import UInt32

    from rabbit_policy.learning.env import ActionBounds
    from rabbit_policy.runtime.memory import MemoryConfig
    from rabbit_policy.runtime.network import HZDPolicyNet, PolicyCheckpoint, widen_inputs

    bounds = ActionBounds.from_library(GaitLibrary.load())
    net = widen_inputs(HZDPolicyNet(bounds.low, bounds.high), 25)
    path = tmp_path / "memory.pt"
    PolicyCheckpoint(net.state_dict(), bounds.low, bounds.high,
                     {"features": "memory", "memory": MemoryConfig.for_period(20).to_dict(),
                      "config": {"decision_period": 20}}).save(path)
    with ros_context() as (context, executor):
        policy = PolicyNode(context=context, policy="learned", policy_file=str(path))
        user = context_node(context)
        pub = user.create_publisher(UInt32, topics.RESETS, qos.STATUS_QOS)
        executor.add_node(policy)
        executor.add_node(user)
        memory = policy.policy.memory
        assert memory is not None
        pub.publish(UInt32(data=1))  # the start: nothing to forget
        assert spin_until(executor, lambda: policy.core.placements == 1)
        memory.inputs(np.array([1.0, 0.9, 0.1]))  # some error integrated
        assert memory.integral != 0.0
        pub.publish(UInt32(data=2))  # a reset
        assert spin_until(executor, lambda: policy.core.placements == 2)
        assert memory.integral == 0.0
        for node in (policy, user):
            executor.remove_node(node)
            node.destroy_node()


@pytest.mark.parametrize("hip_source", ["state_batch", "hip_velocity"])
def test_a_body_state_policy_without_the_controllers_phase_gives_its_decisions_up_logged(tmp_path, hip_source):
    """A controller that publishes no /hzd/phase (another one, or none): policy_node keeps
    running, gives each due decision up once states 50 ticks newer are in (counted, logged)
    and decides again as soon as the phase comes; the states from the simulator's batches or
    from the 1 kHz topics alike."""
    import array

    from geometry_msgs.msg import TwistStamped
    from std_msgs.msg import Float64MultiArray

    from rabbit_msgs_py.conversions import phase_to_msg, stamp_from_ns
    from rabbit_msgs_py.joints import JOINT_NAMES

    path = residual_policy_file(tmp_path / "body_kind.pt", features="body")
    signer = BatchSigner()
    with ros_context() as (context, executor):
        policy = PolicyNode(context=context, policy="learned", policy_file=path, hip_source=hip_source)
        user = context_node(context)
        hip = user.create_publisher(TwistStamped, topics.HIP_VELOCITY, qos.HIP_VELOCITY_QOS)
        states = user.create_publisher(JointState, topics.JOINT_STATES, qos.STREAM_QOS)
        batches = user.create_publisher(Float64MultiArray, topics.STATE_BATCH, qos.BATCH_QOS)
        phase = user.create_publisher(JointState, topics.PHASE, qos.STREAM_QOS)
        for node in (policy, user):
            executor.add_node(node)
        inputs = ((topics.STATE_BATCH,) if hip_source == "state_batch" else (topics.HIP_VELOCITY, topics.JOINT_STATES))
        assert spin_until(executor, lambda: all(user.count_subscribers("/" + topic) == 1 for topic in
                                                inputs + (topics.PHASE,)))
        assert policy.decisions == 1  # the start

        def send(tick: int, with_phase: bool) -> None:
            stamp = stamp_from_ns(tick * 1_000_000)
            if with_phase:  # the controller's phase on the state before
                phase.publish(phase_to_msg(0.5, 2.0, stamp_from_ns((tick - 1) * 1_000_000), "left_foot"))
            position = [0.1 * tick / 1000, 0.8, 0.05, 0.2, 0.3, -0.2, 0.4]
            velocity = [1.0, 0.0, -0.1, 0.0, 0.0, 0.0, 0.0]
            if hip_source == "state_batch":  # signed as a simulator started by hand signs them (the user's key)
                batches.publish(signer.batch(array.array("d", [tick * 1_000_000] + position + velocity + [0.0] * 7), 1))
                return
            states.publish(JointState(header=Header(stamp=stamp), name=list(JOINT_NAMES), position=position,
                                      velocity=velocity))
            msg = TwistStamped()
            msg.header.stamp = stamp
            msg.twist.linear.x = 1.0
            hip.publish(msg)

        def taken(tick: int) -> bool:  # each state taken before the next is sent: none dropped
            return policy.body.newest_state == policy.clock.newest == tick * 1_000_000

        for tick in range(1, 80):
            send(tick, with_phase=False)
            assert spin_until(executor, lambda: taken(tick))
        assert spin_until(executor, lambda: policy.decisions_given_up >= 1)
        assert policy.decisions == 1 and len(policy.core.awaiting) >= 1  # 40 and 60 wait, 20 was given up
        for tick in range(80, 130):
            send(tick, with_phase=True)
            assert spin_until(executor, lambda: taken(tick) and policy.body.newest_phase == (tick - 1) * 1_000_000)
        assert spin_until(executor, lambda: policy.decisions >= 2)  # 100 and 120 decided on their body state
        assert policy.last_observation.body == (0.05, -0.1, 0.5, 2.0, 1.0)
        assert policy.decisions_given_up == 3  # 20, 40 and 60: no phase within 50 ticks before them
        for node in (policy, user):
            executor.remove_node(node)
            node.destroy_node()

