"""Every numeric parameter of every node holds its declared range whatever type the value
arrives as: an integer for a double is converted and range-checked, on the command line and
at run time (``ros2 param set /hzd_controller_node kp 200000`` once said "successful"), and
``ros2 param describe`` shows the declared type."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
import rclpy
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter

from rabbit_hzd_controller.hzd_controller_node import CONTROLLER_PARAMS, NODE_PARAMS, HZDControllerNode
from rabbit_msgs_py.parameters import declare
from rabbit_msgs_py.node_runner import NodeStartError
from rabbit_policy.policy_node import POLICY_PARAMS
from rabbit_sim.recorder_node import RECORDER_PARAMS
from rabbit_sim.sim_node import SIM_PARAMS, SimNode

from ros_helpers import ros_context

pytestmark = pytest.mark.ros

ALL_PARAMS = {"sim_node": SIM_PARAMS, "hzd_controller_node": {**CONTROLLER_PARAMS, **NODE_PARAMS},
              "policy_node": POLICY_PARAMS, "recorder_node": RECORDER_PARAMS}
NUMERIC = [(node, name, spec) for node, params in ALL_PARAMS.items() for name, spec in params.items() if spec.numeric]


def _values(spec) -> list[tuple[object, bool]]:
    """(value, inside the range) at and past both ends, as integers (where the end is whole)
    and as floats."""
    low, high = spec.range
    past = max(0.5, abs(high) * 1e-3)  # (rclpy takes a double within about 1e-9 of an end as the end)
    cases = [(float(low), True), (float(high), True), (float(low) - 0.5, False), (float(high) + past, False)]
    cases += [(math.floor(low) - 1, False), (math.ceil(high + past), False)]
    cases += [(int(end), True) for end in (low, high) if float(end).is_integer()]
    if isinstance(spec.default, int):  # an integer parameter takes integers only
        cases = [(v, ok) for v, ok in cases if isinstance(v, int)]
    return cases


def test_every_numeric_parameter_has_a_range():
    assert NUMERIC and all(spec.range is not None for _node, _name, spec in NUMERIC), \
        [f"{node}.{name}" for node, name, spec in NUMERIC if spec.range is None]


@pytest.mark.parametrize("node_name, name, spec", NUMERIC, ids=[f"{n}.{p}" for n, p, _ in NUMERIC])
def test_a_numeric_parameter_holds_its_range_at_start_and_at_run_time(node_name, name, spec):
    declared = ParameterType.PARAMETER_DOUBLE if isinstance(spec.default, float) else ParameterType.PARAMETER_INTEGER
    with ros_context() as (context, _executor):
        for value, inside in _values(spec):
            node = rclpy.create_node(f"start_{node_name}", context=context,
                                     cli_args=["--ros-args", "-p", f"{name}:={value!r}"])
            try:
                if inside:
                    got = declare(node, {name: spec}, {})[name]
                    assert got == value and type(got) is type(spec.default), (value, got)
                else:
                    with pytest.raises(NodeStartError, match=f"parameter {name} must be in"):
                        declare(node, {name: spec}, {})
            finally:
                node.destroy_node()
        node = rclpy.create_node(f"run_{node_name}", context=context)
        try:
            declare(node, {name: spec}, {})
            assert node.describe_parameter(name).type == declared
            for value, inside in _values(spec):
                result = node.set_parameters_atomically([Parameter(name, value=value)])
                if not spec.dynamic:
                    assert not result.successful and "read-only" in result.reason
                    continue
                assert result.successful == inside, (value, result.reason)
                if inside:
                    got = node.get_parameter(name).value
                    assert got == value and type(got) is type(spec.default)
                    assert node.describe_parameter(name).type == declared
        finally:
            node.destroy_node()


def test_the_nodes_refuse_an_integer_past_the_range_at_run_time():
    """The issue's two rows on the real nodes: kp 200000 (range up to 1e5) and push_duration
    20 (up to 10) as integers are refused, and the node keeps its value and its type."""
    with ros_context() as (context, executor):
        controller = HZDControllerNode(context=context)
        sim = SimNode(context=context)
        executor.add_node(controller)
        executor.add_node(sim)
        for node, name, bad, good in ((controller, "kp", 200000, 3000), (sim, "push_duration", 20, 2)):
            before = node.get_parameter(name).value
            result = node.set_parameters_atomically([Parameter(name, value=bad)])
            assert not result.successful and "range" in result.reason.lower(), result.reason
            assert node.get_parameter(name).value == before
            assert node.set_parameters_atomically([Parameter(name, value=good)]).successful
            assert node.get_parameter(name).value == float(good)
            assert node.describe_parameter(name).type == ParameterType.PARAMETER_DOUBLE
        assert controller.config.kp == 3000.0 and sim.settings.push_duration == 2.0


@pytest.mark.slow
def test_an_integer_past_the_range_on_the_command_line_is_one_line():
    out = subprocess.run([sys.executable, "-m", "rabbit_hzd_controller.hzd_controller_node", "--ros-args",
                          "-p", "kp:=200000"], capture_output=True, text=True, timeout=60)
    errors = [line for line in (out.stdout + out.stderr).splitlines() if line.startswith("error:")]
    assert out.returncode == 1 and len(errors) == 1, out.stdout + out.stderr
    assert "parameter kp must be in [0.001, 100000], got 200000" in errors[0]
