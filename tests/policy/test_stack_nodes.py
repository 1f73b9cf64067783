"""The ROS 2 node stack, spun in the test process with real MuJoCo (lockstep unless said):
walking, speed commands, determinism against the ROS-free loop, reset, bad input and a
controller restart."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, Header, String
from std_srvs.srv import Trigger

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.conversions import alpha_to_msg
from rabbit_msgs_py.decision_ticks import DecisionTiming
from rabbit_msgs_py.pairing import new_key
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.policy_node import PolicyNode
from rabbit_policy.bringup import processes as processes_module
from rabbit_policy.bringup.config import StackConfig
from rabbit_policy.bringup.in_process import run_in_process
from rabbit_policy.bringup.processes import run_multi_process
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.spec.make import make_policy
from rabbit_sim.sim_node import SimNode

from ros_helpers import BatchSigner, ros_context, spin_for, spin_until, spinning, wait_until

pytestmark = pytest.mark.ros


def _recorder(store: list):
    def factory(context):
        import rclpy

        node = rclpy.create_node("trajectory_recorder", context=context)
        node.create_subscription(
            JointState, topics.JOINT_STATES,
            lambda m: store.append(list(m.position) + list(m.velocity)), qos.STREAM_QOS,
        )
        return node
    return factory


def _reference(duration: float, speed: float = 1.0, policy=None, scenario: Scenario | None = None) -> np.ndarray:
    """Every state of the ROS-free loop (default: classic, every 20 ticks, as policy_node)."""
    loop = ClosedLoop(scenario or Scenario.constant(speed), policy or make_policy("classic"))
    data = loop.data
    rows = [data.qpos.tolist() + data.qvel.tolist()]
    for _ in range(int(round(duration / 0.001))):
        loop.tick()
        rows.append(data.qpos.tolist() + data.qvel.tolist())
    return np.array(rows)


@pytest.mark.slow
def test_lockstep_and_paced_runs_match_the_ros_free_loop_bit_for_bit():
    """Lockstep, and paced mode (lockstep held to the wall clock, here at 4x real time),
    publish every state of the ROS-free loop bit for bit; paced takes at least the wall time
    its target real-time factor asks (a lower bound: a slower machine only takes longer)."""
    # classic's own decisions, every 20 ticks, applied at once: the controller holds the
    # reply to each due state until its decision is in (decision_sync)
    reference = _reference(2.0)
    for mode in ("lockstep", "paced"):
        config = StackConfig(duration=2.0, schedule=((0.0, 1.0),), mode=mode, rtf=4.0)
        states: list = []
        report, nodes = run_in_process(config, observers=[_recorder(states)])
        assert report.completed and not report.fell
        assert nodes["sim_node"].torques_rejected == 0
        # a re-sent state (start-up, see sim_node) shows up twice in a row: keep one
        unique = np.array([row for i, row in enumerate(states) if i == 0 or row != states[i - 1]])
        assert unique.shape == reference.shape and np.array_equal(unique, reference), mode
        controller = nodes["hzd_controller_node"]
        assert controller.decisions_waited == 2000 // 20 and controller.decisions_timed_out == 0
        if mode == "paced":
            assert report.wall_time >= 0.9 * 2.0 / 4.0
            assert nodes["sim_node"].statistics()["achieved_rtf"] <= 4.0 * 1.05


@pytest.mark.slow
def test_the_stack_runs_walk_pys_model_error_scenarios_as_the_ros_free_loop():
    """Foot friction, torso mass and a torque delay as sim_node parameters (run_stack's
    --friction, --torso-mass-scale, --torque-delay): lockstep publishes every state of the
    ROS-free loop on the same scenario (walk.py's), bit for bit, and the report says which model
    it ran."""
    config = StackConfig(duration=1.5, schedule=((0.0, 1.0),), friction=0.5, torso_mass_scale=1.15,
                         torque_delay=0.003)
    scenario = config.scenario()
    assert (scenario.model.friction, scenario.model.torso_mass_scale, scenario.torque_delay) == (0.5, 1.15, 0.003)
    assert config.node_parameters()["sim_node"]["torque_delay"] == 0.003
    reference = _reference(1.5, scenario=scenario)
    assert not np.array_equal(reference, _reference(1.5))  # the model errors change the walk
    states: list = []
    report, _nodes = run_in_process(config, observers=[_recorder(states)])
    assert report.completed and not report.fell
    unique = np.array([row for i, row in enumerate(states) if i == 0 or row != states[i - 1]])
    assert unique.shape == reference.shape and np.array_equal(unique, reference)
    assert report.summary()["scenario"]["model"] == {"variant": "paper", "friction": 0.5, "torso_mass_scale": 1.15}
    with pytest.raises(ValueError, match="torque_delay"):
        StackConfig(duration=1.0, schedule=((0.0, 1.0),), torque_delay=0.0025)


@pytest.mark.slow
def test_the_controller_publishes_its_reference_and_tracking_error_when_asked():
    """``reference_rate`` (run_stack --reference-rate): /hzd/reference and /hzd/tracking_error
    at that rate of sim time, the four actuated joints, errors a walking robot keeps small;
    off by default (no such publisher)."""
    from sensor_msgs.msg import JointState as Joints

    seen: dict[str, list] = {topics.REFERENCE: [], topics.TRACKING_ERROR: []}

    def listener(context):
        import rclpy

        node = rclpy.create_node("reference_listener", context=context)
        for topic, store in seen.items():
            node.create_subscription(Joints, topic, lambda m, s=store: s.append(m), qos.STREAM_QOS)
        return node

    config = StackConfig(duration=2.0, schedule=((0.0, 1.0),), reference_rate=100.0)
    report, nodes = run_in_process(config, observers=[listener])
    assert report.completed and not report.fell
    reference, error = seen[topics.REFERENCE], seen[topics.TRACKING_ERROR]
    assert 150 <= len(reference) <= 201 and len(error) == len(reference)  # 100 per s of sim time
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in reference]
    assert np.allclose(np.diff(stamps), 0.01, atol=1e-6)
    assert list(reference[0].name) == ["left_hip", "left_knee", "right_hip", "right_knee"]
    late = np.array([m.position for m in error if m.header.stamp.sec >= 1])
    assert np.abs(late).max() < 0.2  # rad: tracked
    default = StackConfig(duration=1.0, schedule=((0.0, 1.0),))
    assert default.node_parameters()["hzd_controller_node"]["reference_rate"] == 0.0


def _residual_integral_policy_file(path, features: str = "memory") -> str:
    """A learned policy of the final run's kind, saved as train.py saves one: memory inputs
    (or ``body``: the body state too), a residual on the library at v_d + 0.3 x the speed
    integral, and a small nonzero residual (the last layer perturbed, and for ``body`` the
    weights of the body inputs), so the network's output and those inputs matter."""
    import torch

    from rabbit_policy.learning.warm_start import zero_residual_network
    from rabbit_policy.runtime.actions import RESIDUAL_SCALE, policy_bounds
    from rabbit_policy.runtime.memory import INPUTS, MemoryConfig
    from rabbit_policy.runtime.network import PolicyCheckpoint

    library = GaitLibrary.load()
    bounds = policy_bounds("residual", library)
    net = zero_residual_network(bounds.low, bounds.high, INPUTS[features], seed=5)
    with torch.no_grad():
        net.body[-1].bias.uniform_(-0.05, 0.05, generator=torch.Generator().manual_seed(5))
        if features == "body":  # the last layer reads the hidden units, which read the five body inputs
            net.body[-1].weight.uniform_(-0.02, 0.02, generator=torch.Generator().manual_seed(6))
    PolicyCheckpoint(net.state_dict(), bounds.low, bounds.high,
                     {"features": features, "action": "residual", "residual_scale": list(RESIDUAL_SCALE),
                      "integral_gain": 0.3,
                      "memory": MemoryConfig.for_features(features, 20, 0.3, library.speed_range).to_dict(),
                      "config": {"decision_period": 20}}).save(path)
    return str(path)


@pytest.mark.slow
def test_lockstep_runs_a_learned_memory_policy_on_the_speed_integral_as_the_ros_free_loop(tmp_path):
    """The final run's kind of policy through the stack: policy_node builds its memory (the
    speed integral and the last action) from /hip_velocity and its own decisions, the
    residual's base gait moves with the integral (the ``drives`` model walks too slow, so it
    does), and lockstep publishes every state of the ROS-free loop bit for bit."""
    from rabbit_sim.model import ModelOptions

    path = _residual_integral_policy_file(tmp_path / "final_kind.pt")
    policy = make_policy("learned", policy_file=path)
    reference = _reference(2.0, policy=policy, scenario=Scenario.constant(1.0, model=ModelOptions("drives")))
    config = StackConfig(duration=2.0, schedule=((0.0, 1.0),), controller="learned", policy_file=path,
                         model="drives")
    states: list = []
    report, nodes = run_in_process(config, observers=[_recorder(states)])
    assert report.completed and not report.fell
    unique = np.array([row for i, row in enumerate(states) if i == 0 or row != states[i - 1]])
    assert unique.shape == reference.shape and np.array_equal(unique, reference)
    memory = nodes["policy_node"].policy.memory
    assert memory.integral > 0.0  # too slow on drives: the base gait was offset upwards
    assert nodes["hzd_controller_node"].decisions_timed_out == 0


@pytest.mark.slow
def test_lockstep_runs_a_body_state_policy_as_the_ros_free_loop(tmp_path):
    """Row c/d's kind of policy through the stack: policy_node builds the body state of each
    decision from /joint_states (torso pitch and rate, hip velocity of the state decided on)
    and /hzd/phase (the controller's phase on the state before), and lockstep publishes
    every state of the ROS-free loop bit for bit, through a speed change."""
    path = _residual_integral_policy_file(tmp_path / "body_kind.pt", features="body")
    policy = make_policy("learned", policy_file=path)
    assert policy.needs_body
    schedule = ((0.0, 1.0), (1.0, 1.3))
    reference = _reference(2.0, policy=policy, scenario=Scenario(schedule=schedule))
    config = StackConfig(duration=2.0, schedule=schedule, controller="learned", policy_file=path)
    states: list = []
    report, nodes = run_in_process(config, observers=[_recorder(states)])
    assert report.completed and not report.fell
    unique = np.array([row for i, row in enumerate(states) if i == 0 or row != states[i - 1]])
    assert unique.shape == reference.shape and np.array_equal(unique, reference)
    node = nodes["policy_node"]
    assert node.decisions_given_up == 0 and node.last_observation.body is not None
    assert nodes["hzd_controller_node"].decisions_waited == 2000 // 20


@pytest.mark.slow
def test_paced_mode_is_lockstep_held_to_the_wall_clock():
    """Paced at 1x for 1.5 s of sim time in one process: at least ~1.5 s of wall time, the
    robot walks; on a machine too slow for 1x it only takes longer."""
    config = StackConfig(duration=1.5, schedule=((0.0, 1.0),), mode="paced")
    report, nodes = run_in_process(config)
    assert report.completed and not report.fell
    assert report.wall_time >= 0.9 * 1.5
    stats = nodes["sim_node"].statistics()
    assert stats["ticks"] == 1500 and stats["achieved_rtf"] <= 1.05


@pytest.mark.slow
def test_stack_walks_and_cmd_speed_changes_the_speed():
    config = StackConfig(duration=12.0, schedule=((0.0, 0.8), (6.0, 1.3)))
    report, nodes = run_in_process(config)
    assert report.completed and not report.fell
    slow, fast = (segment["mean_speed"] for segment in report.segments)
    assert slow == pytest.approx(0.8, abs=0.05)
    # the classic controller switches gait at once but settles slowly (measured 1.16 m/s
    # over 9-12 s for the 1.3 m/s gait); the command clearly takes effect
    assert fast > slow + 0.25
    assert report.steps >= 18
    # the policy (classic's default) decided once at start and every 20 ticks of sim time
    assert nodes["policy_node"].decisions == pytest.approx(12.0 / 0.020 + 1, abs=3)


@pytest.mark.slow
def test_decisions_every_n_ticks_walk_through_the_stack_with_gaits_applied_at_once():
    config = StackConfig(duration=6.0, schedule=((0.0, 1.0), (3.0, 1.2)), decision=DecisionTiming(50))
    report, nodes = run_in_process(config)
    assert report.completed and not report.fell and not report.stalled
    assert nodes["hzd_controller_node"].gait_timing == "at_once"  # told by policy_node on /hzd/gait_timing
    # about one decision per 50 ms of sim time (plus the one at start), not one per step
    assert nodes["policy_node"].decisions == pytest.approx(6.0 / 0.05, abs=3)
    assert report.steps < 20
    assert nodes["hzd_controller_node"].rejected_gaits == 0


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
    from rabbit_msgs_py.runtime import NodeStartError

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
    from rabbit_msgs_py.pairing import PairingKey, new_key

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


def _start_stack(context, executor, **sim_params):
    nodes = {
        "policy": PolicyNode(context=context),
        "controller": HZDControllerNode(context=context),
        "sim": SimNode(context=context, **sim_params),
    }
    for node in nodes.values():
        executor.add_node(node)
    return nodes


@pytest.mark.slow
def test_reset_service_puts_the_robot_back_on_the_gait():
    with ros_context() as (context, executor):
        import rclpy

        nodes = _start_stack(context, executor)
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


def _call(executor, client, request):
    future = client.call_async(request)
    assert spin_until(executor, future.done)
    return future.result()


def test_resets_never_wedge_lockstep():
    """Back-to-back resets, and a reset while paused at t = 0 followed by unpausing: the
    placed state equals the one the controller already answered, yet it is answered (the
    reset is an event the controller hears, not inferred from stamps or values)."""
    from std_srvs.srv import SetBool

    with ros_context() as (context, executor):
        import rclpy

        nodes = _start_stack(context, executor, start_paused=True)
        sim = nodes["sim"]
        user = rclpy.create_node("resetter", context=context)
        executor.add_node(user)
        reset = user.create_client(Trigger, topics.RESET_SERVICE)
        pause = user.create_client(SetBool, topics.PAUSE_SERVICE)
        assert spin_until(executor, lambda: reset.service_is_ready() and pause.service_is_ready())
        assert spin_until(executor, lambda: sim.lockstep.held_torques is not None)  # t = 0 answered, paused
        assert _call(executor, reset, Trigger.Request()).success  # a reset while paused at t = 0
        assert _call(executor, pause, SetBool.Request(data=False)).success
        assert spin_until(executor, lambda: sim.time >= 0.3, timeout=10.0), f"stuck at t = {sim.time}"
        for _ in range(20):  # back to back
            assert _call(executor, reset, Trigger.Request()).success
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

        nodes = _start_sim_and_policy(context, executor)
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


def _start_sim_and_policy(context, executor, **sim_params):
    nodes = {"policy": PolicyNode(context=context, pairing_key=sim_params.get("pairing_key", "")),  # the stack's key
             "sim": SimNode(context=context, **sim_params)}
    for node in nodes.values():
        executor.add_node(node)
    return nodes


@pytest.mark.slow
def test_a_policy_that_stops_deciding_never_wedges_decision_sync():
    """Lockstep with decision_sync: the policy node goes away mid-walk, so the decision
    due on the next 20th tick never comes. The controller gives it up after
    decision_timeout, answers with the gait in force (once: later due states do not
    wait) and the walk goes on."""
    with ros_context() as (context, executor):
        nodes = _start_sim_and_policy(context, executor)
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
def test_nodes_started_by_hand_run_the_learned_spec_bit_for_bit_as_walk_py(capfd):
    """The three nodes started as ``ros2 run`` starts them, ``policy:=learned`` and nothing
    else: the policy announces its spec's controller settings, signed with the user's key, and
    the controller runs with them before the policy's first gait; the simulator says it runs
    lockstep, so the controller holds each due state for its decision: every state is the
    ROS-free loop's (walk.py's) bit for bit. A controller started with one of the settings given
    otherwise takes none of them and says which in one line."""
    from rabbit_hzd_controller.controller import ControllerConfig
    from rabbit_policy.runtime.policies import controller_settings

    learned = make_policy("learned")
    wanted = controller_settings(learned)
    assert wanted["within_step_blend"] == 0.0  # not the controller's default (0.2)
    duration = 1.5
    reference = _reference(duration, policy=learned)
    for given in ({}, {"within_step_blend": 0.2}):
        states: list = []
        with ros_context() as (context, executor):
            sim = SimNode(context=context)
            controller = HZDControllerNode(context=context, **given)
            for node in (sim, controller, PolicyNode(context=context, policy="learned"),
                         _recorder(states)(context)):
                executor.add_node(node)
            assert spin_until(executor, lambda: sim.time >= duration + 0.05, timeout=120.0)
            running = {k: getattr(controller.config, k) for k in wanted}
            waited = controller.decisions_waited
        err = capfd.readouterr().err
        if not given:
            assert running == wanted and "running with the policy's controller settings" in err
            unique = [row for i, row in enumerate(states) if i == 0 or row != states[i - 1]]
            walked = np.array(unique[:len(reference)])
            assert walked.shape == reference.shape and np.array_equal(walked, reference)
            assert waited > 0 and "decision_sync on" in err
        else:
            assert running == {**{k: getattr(ControllerConfig(), k) for k in wanted}, **given}
            line = next(line for line in err.splitlines() if "the policy needs" in line)
            assert "within_step_blend:=0" in line and "was started with within_step_blend:=0.2" in line


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

        nodes = _start_sim_and_policy(context, executor, resend_timeout=0.1, pairing_key="none")
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
        nodes = _start_sim_and_policy(context, executor, resend_timeout=0.1, pairing_key=key)
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
        nodes = _start_sim_and_policy(context, executor, mode="realtime", watchdog_timeout=0.05,
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
def test_scheduled_pushes_reach_the_torso_at_their_sim_time():
    from rabbit_policy.experiment.scenario import Push

    from geometry_msgs.msg import WrenchStamped

    from rabbit_msgs_py.conversions import stamp_to_seconds

    applied: list = []

    def watcher(context):
        import rclpy

        node = rclpy.create_node("push_watcher", context=context)
        node.create_subscription(WrenchStamped, topics.PUSH_APPLIED,
                                 lambda m: applied.append((stamp_to_seconds(m.header.stamp), m.wrench.force.x)),
                                 qos.EVENT_QOS)
        return node

    base = StackConfig(duration=2.0, schedule=((0.0, 1.0),))
    pushed = StackConfig(duration=2.0, schedule=((0.0, 1.0),), pushes=(Push(0.5, -60.0, 0.3),))
    _, plain_nodes = run_in_process(base)
    _, pushed_nodes = run_in_process(pushed, observers=[watcher])
    # /push_applied: the push starting at its sim time and ending 0.3 s later
    assert [(round(t, 3), f) for t, f in applied] == [(0.5, -60.0), (0.8, 0.0)]
    assert pushed_nodes["sim_node"].settings.push_schedule == "0.5:-60.0:0.3"  # sim_node applies it itself
    assert pushed_nodes["sim_node"].pushes_applied == 1 and plain_nodes["sim_node"].pushes_applied == 0
    x_plain = float(plain_nodes["sim_node"].sim.data.qpos[0])
    x_pushed = float(pushed_nodes["sim_node"].sim.data.qpos[0])
    assert x_pushed < x_plain - 0.02  # pushed backwards: less distance covered


@pytest.mark.slow
def test_push_topic_applies_good_wrenches_and_rejects_bad_ones():
    from geometry_msgs.msg import Wrench

    with ros_context() as (context, executor):
        import rclpy

        nodes = _start_stack(context, executor)
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


@pytest.mark.slow
def test_realtime_smoke_steps_at_wall_clock_pace_and_reports_its_lateness():
    """Realtime in one process for 2 s: the physics runs in the spinning thread (no physics
    thread), about 1000 ticks per wall second, and the statistics say how late it was.
    No timing target here (that is scripts/bench_stack.py): any machine passes."""
    import threading

    config = StackConfig(duration=2.0, schedule=((0.0, 1.0),), mode="realtime")
    before = threading.active_count()
    report, nodes = run_in_process(config)
    stats = nodes["sim_node"].statistics()
    if stats["halt_reason"] is not None:  # a machine too busy to keep up: halted, and the run says so
        assert not report.completed and "halted" in report.error and not report.fell
    else:
        assert report.completed or report.fell
        assert stats["ticks"] >= 1000
    assert stats["tick_rate_hz"] is not None and stats["tick_rate_hz"] < 1100
    assert 0.0 <= stats["late_fraction"] <= 1.0 and stats["skipped_ticks"] >= 0
    assert stats["latency_max_ms"] >= stats["latency_p99_ms"]
    assert threading.active_count() <= before  # no physics thread left behind


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

        nodes = _start_stack(context, executor)
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


@pytest.mark.slow
@pytest.mark.parametrize("controller, period", [("classic", -1), ("learned", -1), ("learned", 0)])
def test_run_stack_and_walk_report_the_same_keys_and_numbers(controller, period):
    """One bookkeeping: the lockstep stack's report (run_stack.py --json) and the fast
    path's (walk.py --json) for one scenario have the same keys and the same numbers:
    policy_node and the loop decide on the same observations (one DecisionClock), the
    schedule's commands reach both at the same state (floats to 1e-9: the stamps carry
    nanoseconds). With decisions every 20 ticks (the policies' own) the controller holds
    each due state for its decision (decision_sync); once per step too. (Across processes:
    the next test.) The learned policy's observations are where a window off by one
    sample showed."""
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.experiment.result import run_summary
    from rabbit_policy.experiment.scenario import Push, Scenario

    schedule, pushes = ((0.0, 0.9), (1.5, 1.2)), (Push(2.2, -40.0, 0.1),)
    config = StackConfig(duration=3.5, schedule=schedule, pushes=pushes, decision=DecisionTiming.parse(period),
                         controller=controller)
    report = run_in_process(config)[0]
    policy = make_policy(controller, decision=DecisionTiming.parse(period))
    result = walk(policy, Scenario(schedule=schedule, pushes=pushes), 3.5)
    stack, fast = report.summary(), run_summary(controller, policy.name, result, 1.0)
    assert list(stack) == list(fast)

    def same(a, b) -> bool:  # floats to 1e-9 (the stamps carry nanoseconds), all else exactly
        if isinstance(a, dict):
            return isinstance(b, dict) and list(a) == list(b) and all(same(a[k], b[k]) for k in a)
        if isinstance(a, list):
            return isinstance(b, list) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
        if isinstance(a, float) and isinstance(b, float):
            return a == pytest.approx(b, rel=1e-9, abs=1e-9)
        return a == b

    for key in set(fast) - {"wall_time", "real_time_factor"}:
        assert same(stack[key], fast[key]), (key, stack[key], fast[key])
    assert stack["steps"] >= 5 and (controller == "learned" or any(s["reach_time"] for s in stack["segments"]))



@pytest.mark.slow
@pytest.mark.parametrize("layout", ["composed", "separate"])
def test_across_processes_the_recorded_walk_is_the_fast_path_bit_for_bit(tmp_path, layout):
    """The nodes as processes (run_stack.py's layouts: the policy apart from the composed
    simulator and controller, or every node apart), the learned policy deciding every 20
    ticks, pushed, with a speed change: the lockstep trajectory recorded (the recorder is
    flow-controlled, so every state is in the bag) is the fast path's bit for bit, each due
    state held by the controller for its decision, the change commanded at its state by
    policy_node (``speed_schedule``: the same rule as the loop, not the arrival of a
    message)."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    from rabbit_policy.experiment.scenario import Push

    schedule, pushes = ((0.0, 0.9), (0.9, 1.2)), (Push(1.2, -40.0, 0.1),)
    report = run_multi_process(StackConfig(duration=2.0, schedule=schedule, pushes=pushes, controller="learned",
                                           record=str(tmp_path / "bag"), layout=layout))
    assert report.completed and not report.fell
    loop = ClosedLoop(Scenario(schedule=schedule, pushes=pushes), make_policy("learned"))
    reference = [loop.data.qpos.tolist() + loop.data.qvel.tolist()]
    for _ in range(2000):
        loop.tick()
        reference.append(loop.data.qpos.tolist() + loop.data.qvel.tolist())
    typestore = get_typestore(Stores.ROS2_JAZZY)
    states = {}
    with Reader(tmp_path / "bag") as reader:
        connections = [c for c in reader.connections if c.topic == topics.resolve(topics.JOINT_STATES)]
        for connection, _t, raw in reader.messages(connections):
            msg = typestore.deserialize_cdr(raw, connection.msgtype)
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            states[round(stamp / 1e6)] = list(msg.position) + list(msg.velocity)
    assert sorted(states) == list(range(2001))
    assert np.array_equal(np.array([states[i] for i in range(2001)]), np.array(reference))
    # the supervisor took every state from the batches from its first on (the placed state may go out
    # before its subscription is matched: its walk then starts a tick later): its walk is the loop's
    seen = np.round(report.result.times * 1000).astype(int)
    assert seen[0] <= 2 and np.array_equal(seen, np.arange(seen[0], 2001))
    assert [t.time for t in report.result.touchdowns] == [t.time for t in loop.touchdowns]


def _state(t: float, x: float):
    """A one-state ``/sim/state_batch`` message: the state at ``t`` s with the hip at ``x`` m."""
    import array

    from rabbit_msgs_py.conversions import state_batch_to_msg

    return state_batch_to_msg(array.array("d", [round(t * 1e9), x, 0.75] + [0.0] * 19), 1)


def _step(t: float):
    from std_msgs.msg import Header

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


def context_node(context):
    import rclpy

    return rclpy.create_node("reset_publisher", context=context)


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

    path = _residual_integral_policy_file(tmp_path / "body_kind.pt", features="body")
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


@pytest.mark.slow
def test_a_body_state_policy_walks_on_through_resets(tmp_path):
    """Resets mid-step while a body-state decision may be waiting for its parts: policy_node
    forgets the last walk's states, phases and waiting decisions, decides again on the new
    walk's, and gives none up."""
    path = _residual_integral_policy_file(tmp_path / "body_kind.pt", features="body")
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
            assert _call(executor, reset, Trigger.Request()).success
        assert spin_until(executor, lambda: sim.time >= 0.5, timeout=30.0), f"stuck at t = {sim.time}"
        assert policy.decisions >= decided + 20  # every 20 ticks on the new walk
        assert policy.decisions_given_up == 0 and not sim.fallen
        assert policy.body.newest_state <= 0.6e9  # the new walk's states only


@pytest.mark.slow
def test_a_use_sim_time_node_follows_the_simulation_clock():
    """The stack's /clock is the clock a node started with use_sim_time reads (no remap in the
    default namespace): its now() follows the states' sim-time stamps, not the wall clock."""
    import rclpy
    from rclpy.parameter import Parameter

    samples: list[tuple[float, float]] = []  # (state stamp, the node's now()) in s

    def factory(context):
        node = rclpy.create_node("sim_time_user", context=context,
                                 parameter_overrides=[Parameter("use_sim_time", Parameter.Type.BOOL, True)])

        def on_state(msg: JointState) -> None:
            stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            samples.append((stamp, node.get_clock().now().nanoseconds * 1e-9))
        node.create_subscription(JointState, topics.JOINT_STATES, on_state, qos.STREAM_QOS)
        return node

    report, _nodes = run_in_process(StackConfig(duration=2.0, schedule=((0.0, 1.0),)), observers=[factory])
    assert report.completed
    late = [(stamp, now) for stamp, now in samples if stamp > 1.0]
    assert len(late) > 100
    # the ROS clock is the newest /clock: within a few ticks of the state being read, never the wall clock (~1.8e9 s)
    assert all(abs(now - stamp) < 0.05 for stamp, now in late), late[:5]
    assert late[-1][1] > 1.9


def test_a_composed_node_that_cannot_start_ends_the_run_with_its_line_and_leaves_no_process(monkeypatch):
    """run_stack's default layout builds the simulator in its own process: one that cannot start
    (here its viewer without a display) raises its one line after the policy process started,
    and that process is stopped (nothing of the stack is left in the domain)."""
    from rabbit_msgs_py.runtime import NodeStartError

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
