"""Node parameters a ROS user can trust: integers for doubles, one-line errors, validation at
start, read-only parameters refused at run time, run-time changes validated."""

from __future__ import annotations

import subprocess
import sys

import pytest
from rclpy.parameter import Parameter

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py.parameters import coerce
from rabbit_msgs_py.node_runner import NodeStartError
from rabbit_policy.policy_node import PolicyNode
from rabbit_sim.sim_node import SimNode

from ros_helpers import ros_context, wait_until

pytestmark = pytest.mark.ros


def test_coerce_accepts_an_integer_for_a_double_and_nothing_else_odd():
    assert coerce("kp", 3000, 1.0) == 3000.0 and isinstance(coerce("kp", 3000, 1.0), float)
    for value, default in ((True, 1.0), ("fast", 1.0), (1.5, 1), (True, 1), (1, "a")):
        with pytest.raises(ValueError, match="parameter x must be"):
            coerce("x", value, default)


@pytest.mark.slow
@pytest.mark.parametrize("args, message", [
    (["rabbit_hzd_controller.hzd_controller_node", "-p", "kp:=fast"], "parameter kp must be a number"),
    (["rabbit_policy.policy_node", "-p", "policy:=learned", "-p", "policy_file:=/etc/passwd"],
     "not a policy checkpoint"),
    (["rabbit_policy.policy_node", "-p", "policy_file:=/etc/passwd"], "it is for the learned controller"),
    (["rabbit_policy.policy_node", "-p", "initial_speed:=inf"], "parameter initial_speed must be in [0.7, 1.5], got inf"),
    (["rabbit_policy.policy_node", "-p", "initial_speed:=2.0", "-p", "policy:=classic"], "in [0.7, 1.5]"),
    (["rabbit_policy.policy_node", "-p", "min_speed:=0.1"], "parameter min_speed must be in [0.7, 1.5], got 0.1"),
    (["rabbit_sim.sim_node", "-p", "max_late_fraction:=1.5"], "parameter max_late_fraction must be in [0.001, 1]"),
    (["rabbit_sim.sim_node", "-p", "damping:=nan"], "parameter damping must be in [0, 10000], got nan"),
    (["rabbit_sim.sim_node", "-p", "stop_time:=nan"], "parameter stop_time must be in [0, 1e+09], got nan"),
    (["rabbit_sim.sim_node", "-p", "stats_file:=/nonexistent/dir/stats.json"], "does not exist"),
    (["rabbit_sim.sim_node", "-p", "mode:=paced", "-p", "rtf:=0.0"], "parameter rtf must be in [0.001, 1000], got 0.0"),
    (["rabbit_policy.policy_node", "-p", "window:=0", "-p", "decision_period:=20"],
     "parameter window must be in [1, 100000], got 0"),
    (["rabbit_policy.policy_node", "-p", "window:=-5"], "parameter window must be in [1, 100000], got -5"),
    (["rabbit_policy.policy_node", "-p", "policy:=bogus"], "parameter policy must be one of classic, learned, recovery"),
    (["rabbit_sim.recorder_node", "-p", "output:=/tmp/x", "-p", "compression:=lz4"],
     "parameter compression must be one of none, zstd, got 'lz4'"),
])
def test_bad_parameters_stop_a_node_with_one_line(args, message):
    module, *params = args
    out = subprocess.run([sys.executable, "-m", module, "--ros-args", *params], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 1
    errors = [line for line in (out.stdout + out.stderr).splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], out.stdout + out.stderr
    assert "Traceback" not in out.stdout + out.stderr


def test_a_broken_params_file_is_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("sim_node:\n  ros__parameters:\n    mode: [broken\n")
    out = subprocess.run([sys.executable, "-m", "rabbit_sim.sim_node", "--ros-args", "--params-file", str(bad)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 1 and "Traceback" not in out.stdout + out.stderr
    assert [line for line in out.stdout.splitlines() if line.startswith("error:")]


def test_a_node_that_fails_to_start_leaves_the_ros_graph_at_once(tmp_path):
    """A node whose start fails destroys itself before the error propagates: it was seen as a
    running ``policy_node`` by the next ``run_stack.py`` in the domain for as long as a test's
    traceback kept it alive (CI refused a stack for that). The garbage collector is off here,
    as when a traceback holds the node; an observer in the same context sees the graph at once."""
    import gc

    import rclpy

    from rabbit_sim.player import BagPlayer, PlaybackError
    from rabbit_sim.recorder_node import RecorderNode

    failing = [("hzd_controller_node", lambda c: HZDControllerNode(context=c, kp="fast"), NodeStartError),
               ("policy_node", lambda c: PolicyNode(context=c, speed_integral=float("nan")), NodeStartError),
               ("policy_node", lambda c: PolicyNode(context=c, window=0, decision_period=20), NodeStartError),
               ("sim_node", lambda c: SimNode(context=c, damping=float("nan")), NodeStartError),
               ("recorder_node", lambda c: RecorderNode(context=c, output=""), NodeStartError),
               ("rosbag2_player", lambda c: BagPlayer(tmp_path, rate=0.0, context=c), PlaybackError)]
    with ros_context() as (context, _executor):
        observer = rclpy.create_node("observer", context=context)
        names = lambda: {name for name, _ns in observer.get_node_names_and_namespaces()}  # noqa: E731
        started = PolicyNode(context=context)
        assert "policy_node" in names()  # the observer sees a node of its context at once
        started.destroy_node()
        gc.disable()
        try:
            kept = []  # the errors and their tracebacks stay alive, as pytest's would
            for name, make, error in failing:
                with pytest.raises(error) as raised:
                    make(context)
                kept.append(raised)
                assert name not in names(), f"{name} lingers after a failed start: {raised.value}"
        finally:
            gc.enable()
        observer.destroy_node()


def test_a_node_a_test_leaves_alive_is_destroyed_and_fails_the_test():
    """A test took its policy node off the executor (so ros_context did not destroy it) and
    never destroyed it: the node stayed in the xdist worker's domain for the rest of the
    session (gc.freeze in run_in_process keeps it), and every later run_stack there refused
    to start beside "another stack" (CI under load). ros_context now destroys every node of
    its context and fails the test that left one; a node from another context is not
    touched."""
    import gc

    import rclpy

    with ros_context() as (other, _other_executor):
        bystander = rclpy.create_node("bystander", context=other)
        gc.disable()  # as when a traceback or gc.freeze keeps the node: only destroying it helps
        try:
            with pytest.raises(AssertionError, match="left alive by the test.*/policy_node"):
                with ros_context() as (context, executor):
                    left = PolicyNode(context=context)
                    executor.add_node(left)
                    executor.remove_node(left)  # off the executor: ros_context's own cleanup misses it
            with ros_context() as (context, _executor):
                observer = rclpy.create_node("observer", context=context)
                assert wait_until(lambda: "bystander" in observer.get_node_names())
                assert "policy_node" not in observer.get_node_names()
                observer.destroy_node()
        finally:
            gc.enable()
        assert bystander.get_name() == "bystander"  # still alive: not this context's
        bystander.destroy_node()


def test_integer_parameters_where_doubles_are_meant():
    with ros_context() as (context, _executor):
        controller = HZDControllerNode(context=context, kp=3000, max_kd=250)
        assert controller.config.kp == 3000.0 and controller.config.max_kd == 250.0
        controller.destroy_node()
        with pytest.raises(NodeStartError, match="parameter kp must be a number"):
            HZDControllerNode(context=context, kp="fast")


def test_run_time_changes_are_validated_and_read_only_ones_refused():
    with ros_context() as (context, _executor):
        controller = HZDControllerNode(context=context)
        assert controller.set_parameters([Parameter("kp", value=2500.0)])[0].successful
        assert controller.config.kp == 2500.0
        result = controller.set_parameters([Parameter("kp", value=-5.0)])[0]
        assert not result.successful and "kp" in result.reason and controller.config.kp == 2500.0
        assert not controller.set_parameters([Parameter("torque_limit", value=100.0)])[0].successful
        assert controller.config.torque_limit == 150.0
        policy = PolicyNode(context=context, policy="classic")
        assert not policy.set_parameters([Parameter("policy", value="learned")])[0].successful
        assert not policy.set_parameters([Parameter("max_speed", value=0.5)])[0].successful  # below min_speed
        for name, value in (("min_speed", 0.1), ("max_speed", 3.0)):  # beyond the speeds the library walks
            assert not policy.set_parameters([Parameter(name, value=value)])[0].successful
        assert (policy.min_speed, policy.max_speed) == (0.7, 1.5)
        assert policy.set_parameters([Parameter("max_speed", value=1.2)])[0].successful
        assert policy.max_speed == 1.2 and policy.desired_speed <= 1.2
        sim = SimNode(context=context)
        assert not sim.set_parameters([Parameter("mode", value="realtime")])[0].successful
        assert sim.set_parameters([Parameter("push_duration", value=1)])[0].successful  # an integer: fine
        assert sim.settings.push_duration == 1.0
        assert not sim.set_parameters([Parameter("push_duration", value=float("nan"))])[0].successful
        for node in (controller, policy, sim):
            close = getattr(node, "close", None)
            if close:
                close()
            node.destroy_node()


def test_numeric_parameters_carry_their_range_in_the_descriptor_and_rclpy_enforces_it():
    """What ``ros2 param describe`` shows: a floating-point or integer range on every number
    whose description states one; ``ros2 param set`` outside it is refused with the reason."""
    from rabbit_hzd_controller.hzd_controller_node import CONTROLLER_PARAMS, NODE_PARAMS
    from rabbit_policy.policy_node import POLICY_PARAMS
    from rabbit_sim.sim_node import SIM_PARAMS

    with ros_context() as (context, _executor):
        nodes = {"hzd_controller_node": (HZDControllerNode(context=context), {**CONTROLLER_PARAMS, **NODE_PARAMS}),
                 "policy_node": (PolicyNode(context=context), POLICY_PARAMS),
                 "sim_node": (SimNode(context=context), SIM_PARAMS)}
        try:
            for name, (node, params) in nodes.items():
                numbers = [k for k, p in params.items()
                           if isinstance(p.default, (int, float)) and not isinstance(p.default, bool)]
                assert numbers, name
                for key in numbers:
                    descriptor = node.describe_parameter(key)
                    ranges = descriptor.floating_point_range or descriptor.integer_range
                    assert len(ranges) == 1, (name, key)
                    low, high = ranges[0].from_value, ranges[0].to_value
                    assert (low, high) == params[key].range and low <= params[key].default <= high, (name, key)
            controller = nodes["hzd_controller_node"][0]
            result = controller.set_parameters([Parameter("kp", value=2e5)])[0]
            assert not result.successful and "range" in result.reason and controller.config.kp == 3000.0
        finally:
            for node, _params in nodes.values():
                close = getattr(node, "close", None)
                if close:
                    close()
                node.destroy_node()


def test_string_parameters_with_fixed_values_list_them_in_the_descriptor():
    """``ros2 param describe`` shows the allowed values of policy, library_mode, mode, model,
    gait_timing (additional_constraints), the very tuples the nodes check against."""
    from rabbit_hzd_controller.hzd_controller_node import GAIT_TIMINGS
    from rabbit_policy.runtime.policies import CONTROLLER_CHOICES, LIBRARY_MODES
    from rabbit_sim.physics.model import MODEL_VARIANTS
    from rabbit_sim.stepping.settings import MODES

    with ros_context() as (context, _executor):
        nodes = {"hzd_controller_node": HZDControllerNode(context=context), "policy_node": PolicyNode(context=context),
                 "sim_node": SimNode(context=context)}
        try:
            expected = {("policy_node", "policy"): CONTROLLER_CHOICES, ("policy_node", "library_mode"): LIBRARY_MODES,
                        ("sim_node", "mode"): MODES, ("sim_node", "model"): MODEL_VARIANTS,
                        ("hzd_controller_node", "gait_timing"): ("policy",) + GAIT_TIMINGS}
            for (name, key), choices in expected.items():
                assert nodes[name].describe_parameter(key).additional_constraints == "one of: " + ", ".join(choices)
        finally:
            for node in nodes.values():
                close = getattr(node, "close", None)
                if close:
                    close()
                node.destroy_node()


def test_an_unknown_parameter_is_named_in_the_log(capfd):
    """A parameter the node does not have (``initial_speed`` was removed from sim_node) is
    not taken silently: one warning names it; the node still starts."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, args=["--ros-args", "-p", "initial_speed:=1.2", "-p", "mode:=lockstep"])
    try:
        sim = SimNode(context=context)
        sim.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    err = capfd.readouterr().err
    assert "ignoring unknown parameter(s) initial_speed" in err and "mode" not in err.split("ignoring")[1][:40]


def test_importing_a_node_sets_nothing_and_starting_ros_sets_the_discovery_default():
    """No import-time side effects: the localhost discovery default is set where a process
    starts ROS (``init_context``, ``run_node``, the scripts' ``main``), not on import."""
    import os
    import subprocess
    import sys

    code = ("import os, rabbit_sim.sim_node, rabbit_sim.recorder_node, rabbit_policy.policy_node, "
            "rabbit_hzd_controller.hzd_controller_node, rabbit_policy.bringup.processes\n"
            "print(os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'))\n"
            "from rabbit_msgs_py.node_runner import init_context\n"
            "init_context().try_shutdown()\n"
            "print(os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE'))\n")
    env = {k: v for k, v in os.environ.items() if k != "ROS_AUTOMATIC_DISCOVERY_RANGE"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["None", "LOCALHOST"]


# parameters whose accepted values also depend on another one: set so that the range's ends are reachable
_COMPANIONS = {("policy_node", "min_speed"): {"initial_speed": 1.5},
               ("policy_node", "max_speed"): {"initial_speed": 0.7}}


def _starts(node_class, context, overrides: dict) -> bool:
    """Whether the node starts with these parameter values (a refused one: NodeStartError)."""
    try:
        node = node_class(context=context, **overrides)
    except NodeStartError:
        return False
    close = getattr(node, "close", None)
    if close:
        close()
    node.destroy_node()
    return True


@pytest.mark.slow
def test_every_numeric_descriptor_range_is_exactly_what_the_node_accepts():
    """``ros2 param describe``'s range is the whole truth: each end of every numeric parameter's
    range starts the node, and a value just outside either end is refused (one source: the
    descriptor's range is the check; a stricter check inside the node would make an end fail)."""
    from rabbit_hzd_controller.hzd_controller_node import CONTROLLER_PARAMS, NODE_PARAMS
    from rabbit_policy.policy_node import POLICY_PARAMS
    from rabbit_sim.sim_node import SIM_PARAMS

    nodes = {"hzd_controller_node": (HZDControllerNode, {**CONTROLLER_PARAMS, **NODE_PARAMS}),
             "policy_node": (PolicyNode, POLICY_PARAMS), "sim_node": (SimNode, SIM_PARAMS)}
    wrong = []
    with ros_context() as (context, _executor):
        for name, (node_class, params) in nodes.items():
            for key, spec in params.items():
                if spec.range is None:
                    continue
                companions = _COMPANIONS.get((name, key), {})
                low, high = spec.range
                integer = isinstance(spec.default, int)
                step = 1 if integer else max(abs(low) * 1e-3, 1e-6)
                for value, accepted in ((low, True), (high, True), (low - step, False),
                                        (high + (1 if integer else max(abs(high) * 1e-3, 1e-6)), False)):
                    if _starts(node_class, context, {**companions, key: value}) != accepted:
                        wrong.append(f"{name} {key}={value!r}: {'refused' if accepted else 'accepted'}")
    assert not wrong, "\n".join(wrong)
