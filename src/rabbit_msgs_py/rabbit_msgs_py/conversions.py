"""Conversions between ROS messages and the plain values the ROS-free cores use (needs
the message packages, not an rclpy context).

alpha travels as std_msgs/Float64MultiArray holding a 4 x 6 matrix, row-major:
``dim[0] = ("output", size 4, stride 24)``, ``dim[1] = ("coefficient", size 6, stride 6)``,
``data_offset = 0``; so ``data[6 j + k]`` is Bezier coefficient k (0..5) of output j, and
the outputs are (stance hip, stance knee, swing hip, swing knee), rad. The ROS-free core
keeps the paper's coefficient-major 24-vector (``flat[4 k + j]``, see
``rabbit_hzd_controller.alpha``); these functions transpose between the two.
Joint torques travel as a one-dimensional Float64MultiArray labelled ``joint`` in
``ACTUATED_JOINTS`` order.
"""

from __future__ import annotations

import math
from typing import Sequence

from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from .joints import ACTUATED_JOINTS, JOINT_NAMES

ALPHA_OUTPUTS = 4
ALPHA_COEFFICIENTS = 6
ALPHA_SIZE = ALPHA_OUTPUTS * ALPHA_COEFFICIENTS
ALPHA_DIMENSIONS = ("output", "coefficient")
TORQUE_DIMENSION = "joint"


class MessageError(ValueError):
    """A message that does not have the documented layout or contents."""


def alpha_to_msg(alpha: Sequence[float]) -> Float64MultiArray:
    """24 coefficients (core order, coefficient-major) -> Float64MultiArray, 4 x 6 layout."""
    values = [float(a) for a in alpha]
    if len(values) != ALPHA_SIZE:
        raise MessageError(f"alpha needs {ALPHA_SIZE} values, got {len(values)}")
    layout = MultiArrayLayout(
        dim=[
            MultiArrayDimension(label=ALPHA_DIMENSIONS[0], size=ALPHA_OUTPUTS, stride=ALPHA_SIZE),
            MultiArrayDimension(label=ALPHA_DIMENSIONS[1], size=ALPHA_COEFFICIENTS, stride=ALPHA_COEFFICIENTS),
        ],
        data_offset=0,
    )
    data = [values[ALPHA_OUTPUTS * k + j] for j in range(ALPHA_OUTPUTS) for k in range(ALPHA_COEFFICIENTS)]
    return Float64MultiArray(layout=layout, data=data)


def alpha_from_msg(msg: Float64MultiArray) -> list[float]:
    """Float64MultiArray (4 x 6 layout) -> 24 coefficients in core order; raises
    :class:`MessageError` on a wrong layout, size or non-finite value. An empty layout is
    accepted if ``data`` has 24 values (then read as the documented 4 x 6 order)."""
    data = list(msg.data)
    dims = list(msg.layout.dim)
    if dims:
        shape = [(d.label, d.size) for d in dims]
        expected = [(ALPHA_DIMENSIONS[0], ALPHA_OUTPUTS), (ALPHA_DIMENSIONS[1], ALPHA_COEFFICIENTS)]
        if shape != expected:
            raise MessageError(f"alpha layout must be {expected}, got {shape}")
        if msg.layout.data_offset != 0:
            raise MessageError("alpha layout data_offset must be 0")
    if len(data) != ALPHA_SIZE:
        raise MessageError(f"alpha needs {ALPHA_SIZE} values, got {len(data)}")
    if not all(math.isfinite(v) for v in data):
        raise MessageError("alpha contains NaN or infinite values")
    return [data[ALPHA_COEFFICIENTS * j + k] for k in range(ALPHA_COEFFICIENTS) for j in range(ALPHA_OUTPUTS)]


def torques_to_msg(torques: Sequence[float]) -> Float64MultiArray:
    """4 joint torques (N m, ``ACTUATED_JOINTS`` order) -> Float64MultiArray."""
    values = [float(t) for t in torques]
    if len(values) != len(ACTUATED_JOINTS):
        raise MessageError(f"expected {len(ACTUATED_JOINTS)} torques, got {len(values)}")
    layout = MultiArrayLayout(
        dim=[MultiArrayDimension(label=TORQUE_DIMENSION, size=len(values), stride=len(values))],
        data_offset=0,
    )
    return Float64MultiArray(layout=layout, data=values)


def torques_from_msg(msg: Float64MultiArray) -> list[float]:
    """Float64MultiArray -> 4 torques; raises :class:`MessageError` if malformed."""
    data = list(msg.data)
    if len(data) != len(ACTUATED_JOINTS):
        raise MessageError(f"expected {len(ACTUATED_JOINTS)} torques, got {len(data)}")
    if not all(math.isfinite(v) for v in data):
        raise MessageError("torques contain NaN or infinite values")
    return data


def joint_state_vectors(names: Sequence[str], position: Sequence[float], velocity: Sequence[float]
                        ) -> tuple[list[float], list[float]]:
    """JointState fields -> (q, dq) in ``JOINT_NAMES`` order, whatever order the message
    uses; raises :class:`MessageError` on missing joints or sizes that do not match."""
    names = list(names)
    if len(position) != len(names) or len(velocity) != len(names):
        raise MessageError("joint state needs one position and one velocity per name")
    if tuple(names) == JOINT_NAMES:
        q, dq = list(position), list(velocity)
    else:
        try:
            index = [names.index(n) for n in JOINT_NAMES]
        except ValueError as exc:
            raise MessageError(f"joint state lacks a joint: {exc}") from None
        q, dq = [position[i] for i in index], [velocity[i] for i in index]
    if not all(math.isfinite(v) for v in q) or not all(math.isfinite(v) for v in dq):
        raise MessageError("joint state contains NaN or infinite values")
    return q, dq


def stamp_to_ns(stamp) -> int:
    """builtin_interfaces/Time (``sec``, ``nanosec``) -> integer nanoseconds."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def stamp_to_seconds(stamp) -> float:
    """builtin_interfaces/Time -> seconds (float)."""
    return stamp.sec + stamp.nanosec * 1e-9
