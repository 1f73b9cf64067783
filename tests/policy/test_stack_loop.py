"""The ROS 2 node stack, spun in the test process with real MuJoCo, walks as the ROS-free
loop does: lockstep and paced bit for bit, model errors, learned and body-state policies,
nodes started by hand, across processes, pushes, realtime, run_stack's report and sim time."""

from __future__ import annotations


import numpy as np
import pytest
from sensor_msgs.msg import JointState

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.decision_ticks import DecisionTiming
from rabbit_policy.policy_node import PolicyNode
from rabbit_policy.bringup.config import StackConfig
from rabbit_policy.bringup.in_process import run_in_process
from rabbit_policy.bringup.processes import run_multi_process
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.spec.make import make_policy
from rabbit_sim.sim_node import SimNode

from ros_helpers import ros_context, spin_until
from stack_helpers import loop_states, residual_policy_file, state_recorder

pytestmark = pytest.mark.ros


@pytest.mark.slow
def test_lockstep_and_paced_runs_match_the_ros_free_loop_bit_for_bit():
    """Lockstep, and paced mode (lockstep held to the wall clock, here at 4x real time),
    publish every state of the ROS-free loop bit for bit; paced takes at least the wall time
    its target real-time factor asks (a lower bound: a slower machine only takes longer)."""
    # classic's own decisions, every 20 ticks, applied at once: the controller holds the
    # reply to each due state until its decision is in (decision_sync)
    reference = loop_states(2.0)
    for mode in ("lockstep", "paced"):
        config = StackConfig(duration=2.0, schedule=((0.0, 1.0),), mode=mode, rtf=4.0)
        states: list = []
        report, nodes = run_in_process(config, observers=[state_recorder(states)])
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
    reference = loop_states(1.5, scenario=scenario)
    assert not np.array_equal(reference, loop_states(1.5))  # the model errors change the walk
    states: list = []
    report, _nodes = run_in_process(config, observers=[state_recorder(states)])
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


@pytest.mark.slow
def test_lockstep_runs_a_learned_memory_policy_on_the_speed_integral_as_the_ros_free_loop(tmp_path):
    """The final run's kind of policy through the stack: policy_node builds its memory (the
    speed integral and the last action) from /hip_velocity and its own decisions, the
    residual's base gait moves with the integral (the ``drives`` model walks too slow, so it
    does), and lockstep publishes every state of the ROS-free loop bit for bit."""
    from rabbit_sim.physics.model import ModelOptions

    path = residual_policy_file(tmp_path / "final_kind.pt")
    policy = make_policy("learned", policy_file=path)
    reference = loop_states(2.0, policy=policy, scenario=Scenario.constant(1.0, model=ModelOptions("drives")))
    config = StackConfig(duration=2.0, schedule=((0.0, 1.0),), controller="learned", policy_file=path,
                         model="drives")
    states: list = []
    report, nodes = run_in_process(config, observers=[state_recorder(states)])
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
    path = residual_policy_file(tmp_path / "body_kind.pt", features="body")
    policy = make_policy("learned", policy_file=path)
    assert policy.needs_body
    schedule = ((0.0, 1.0), (1.0, 1.3))
    reference = loop_states(2.0, policy=policy, scenario=Scenario(schedule=schedule))
    config = StackConfig(duration=2.0, schedule=schedule, controller="learned", policy_file=path)
    states: list = []
    report, nodes = run_in_process(config, observers=[state_recorder(states)])
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
    reference = loop_states(duration, policy=learned)
    for given in ({}, {"within_step_blend": 0.2}):
        states: list = []
        with ros_context() as (context, executor):
            sim = SimNode(context=context)
            controller = HZDControllerNode(context=context, **given)
            for node in (sim, controller, PolicyNode(context=context, policy="learned"),
                         state_recorder(states)(context)):
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
    states, steps = {}, []
    with Reader(tmp_path / "bag") as reader:
        wanted = {topics.resolve(topics.JOINT_STATES), topics.resolve(topics.STEP)}
        for connection, _t, raw in reader.messages([c for c in reader.connections if c.topic in wanted]):
            msg = typestore.deserialize_cdr(raw, connection.msgtype)
            header = msg.header if connection.topic != topics.resolve(topics.STEP) else msg
            stamp = header.stamp.sec * 1_000_000_000 + header.stamp.nanosec
            if connection.topic == topics.resolve(topics.STEP):
                steps.append(stamp)
            else:
                states[round(stamp / 1e6)] = list(msg.position) + list(msg.velocity)
    assert sorted(states) == list(range(2001))
    assert np.array_equal(np.array([states[i] for i in range(2001)]), np.array(reference))
    # the supervisor took every state from the batches from its first on (the placed state may go out
    # before its subscription is matched: its walk then starts a tick later): its walk is the loop's
    seen = np.round(report.result.times * 1000).astype(int)
    assert seen[0] <= 2 and np.array_equal(seen, np.arange(seen[0], 2001))
    assert [t.time for t in report.result.touchdowns] == [t.time for t in loop.touchdowns]
    # one touchdown time on every path: /hzd/step's stamps are the touchdowns of both JSONs
    assert steps and [s / 1e9 for s in sorted(steps)] == report.result.summary()["touchdowns"]
    assert loop.result().summary()["touchdowns"] == report.result.summary()["touchdowns"]


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

