"""Node parameters a ROS user can trust (needs rclpy): declared up front with a description
(units, range) and whether they may change at run time, an integer accepted where a double
is meant (``-p kp:=3000``, ``ros2 param set ... kp 3000``, as most ROS nodes do), and
anything else of the wrong type a one-line
:class:`~rabbit_msgs_py.node_runner.NodeStartError` instead of a traceback.

A number is declared with its type fixed (``ros2 param describe`` says "double" or
"integer") and its range (``floating_point_range`` / ``integer_range``). An integer given
for a double is converted to a double before rclpy checks it, on the command line and at
run time (:func:`declare` installs the conversion), so it meets the same range: rclpy
refuses a value outside it, on the command line with one line, on ``ros2 param set`` with
the reason. ``ros2 param set`` on a read-only parameter is refused by rclpy with the
reason. A range is closed: where the description says "> 0" the node's own check refuses 0
too. Strings and booleans keep dynamic typing: a string of digits given on the command line
arrives as an integer, and the node's own check names the parameter in one line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.parameter import Parameter

from .node_runner import NodeStartError

_TYPE_NAMES = {bool: "a boolean", int: "an integer", float: "a number", str: "a string"}


@dataclass(frozen=True)
class Param:
    """One parameter: default (its type is the parameter's), description (say units and
    range), and whether ``ros2 param set`` may change it while the node runs."""

    default: Any
    description: str
    dynamic: bool = False
    range: tuple[float, float] | None = None  # closed [low, high] of a number, in the descriptor
    step: float = 0.0  # a float range's step (values low + k step; 0 = any), in the descriptor
    choices: tuple[str, ...] | None = None  # a string's allowed values, in the descriptor's additional_constraints

    @property
    def numeric(self) -> bool:
        """A number (int or float default, not bool): declared with its type fixed."""
        return isinstance(self.default, (int, float)) and not isinstance(self.default, bool)

    def descriptor(self) -> ParameterDescriptor:
        """The ROS descriptor: description, read-only unless dynamic, the range of a number,
        a string's allowed values (``additional_constraints``: ``ros2 param describe`` shows them)."""
        descriptor = ParameterDescriptor(description=self.description, read_only=not self.dynamic,
                                         dynamic_typing=not self.numeric)
        if self.choices is not None:
            descriptor.additional_constraints = "one of: " + ", ".join(self.choices)
        if self.range is not None:
            low, high = self.range
            if isinstance(self.default, bool) or not isinstance(self.default, (int, float)):
                raise TypeError(f"a range needs a numeric default, not {self.default!r}")
            if isinstance(self.default, int):
                descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
            else:
                descriptor.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high),
                                                                      step=float(self.step))]
        return descriptor


def coerce(name: str, value: Any, default: Any) -> Any:
    """``value`` as the type of ``default`` (an int for a float is fine); raises
    ``ValueError`` with one line naming the parameter otherwise."""
    kind = type(default)
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind is int and isinstance(value, bool) or not isinstance(value, kind):
        raise ValueError(f"parameter {name} must be {_TYPE_NAMES.get(kind, kind.__name__)}, got {value!r}")
    return value


def finite(name: str, value: float, low: float | None = None, high: float | None = None) -> float:
    """``value`` if finite and within [low, high]; else ``ValueError`` naming ``name``."""
    if not math.isfinite(value) or (low is not None and value < low) or (high is not None and value > high):
        bounds = f" in [{low if low is not None else '-inf'}, {high if high is not None else 'inf'}]"
        raise ValueError(f"{name} must be a finite number{bounds if low is not None or high is not None else ''},"
                         f" got {value}")
    return value


def declare(node, params: dict[str, Param], overrides: dict[str, Any]) -> dict[str, Any]:
    """Declare ``params`` on ``node`` (``overrides``: values from the code that builds the
    node, below ``--ros-args``) and return their values, each of its declared type; raises
    :class:`NodeStartError` with one line for a value of the wrong type or out of range.
    Installs :func:`integers_as_doubles` for the run time."""
    doubles = tuple(name for name, spec in params.items() if spec.numeric and isinstance(spec.default, float))
    given = getattr(node, "_parameter_overrides", {})  # the command line's, which wins
    for name in doubles:
        if name in given and given[name].type_ == Parameter.Type.INTEGER:
            given[name] = Parameter(name, Parameter.Type.DOUBLE, float(given[name].value))
    values = {}
    for name, spec in params.items():
        default = overrides.get(name, spec.default)
        try:
            if spec.numeric:
                default = coerce(name, default, spec.default)
            node.declare_parameter(name, default, spec.descriptor())
        except InvalidParameterValueException:
            value = given[name].value if name in given else default
            raise NodeStartError(f"{node.get_name()}: parameter {name} must be in [{spec.range[0]:g}, "
                                 f"{spec.range[1]:g}], got {value!r}") from None
        except (InvalidParameterTypeException, ValueError):
            value = given[name].value if name in given else default
            raise NodeStartError(f"{node.get_name()}: parameter {name} must be "
                                 f"{_TYPE_NAMES[type(spec.default)]}, got {value!r}") from None
        try:
            values[name] = coerce(name, node.get_parameter(name).value, spec.default)
            if spec.choices is not None and values[name] not in spec.choices:
                raise ValueError(f"parameter {name} must be one of {', '.join(spec.choices)}, got {values[name]!r}")
        except ValueError as exc:
            raise NodeStartError(f"{node.get_name()}: {exc}") from None
    unknown = sorted(name for name in overrides_given(node) if not node.has_parameter(name))
    if unknown:
        node.get_logger().warning(f"ignoring unknown parameter(s) {', '.join(unknown)}: {node.get_name()} has no such "
                                  f"parameter (ros2 param list shows those it has)")
    node.add_pre_set_parameters_callback(integers_as_doubles(doubles))
    return values


def integers_as_doubles(names: tuple[str, ...]) -> Callable[[list[Parameter]], list[Parameter]]:
    """A pre-set callback (``Node.add_pre_set_parameters_callback``) that turns an integer
    given for one of the double parameters ``names`` (``ros2 param set /node kp 200000``)
    into that double, so that rclpy checks it against the declared type and range like any
    double; everything else passes unchanged."""
    wanted = frozenset(names)

    def convert(parameters: list[Parameter]) -> list[Parameter]:
        return [Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
                if p.name in wanted and p.type_ == Parameter.Type.INTEGER else p for p in parameters]

    return convert


def forget_secrets(node, names: tuple[str, ...]) -> None:
    """Remove the parameters ``names`` once read (a key given at start): ``ros2 param get``
    and ``ros2 param dump`` cannot read them afterwards. They must be declared dynamic
    (rclpy cannot remove a read-only parameter)."""
    for name in names:
        node.undeclare_parameter(name)


def overrides_given(node) -> list[str]:
    """Names of the parameters set for ``node`` on its command line (``-p name:=value``,
    parameter files), before anything was declared."""
    return [name for name in getattr(node, "_parameter_overrides", {}) if "." not in name]
