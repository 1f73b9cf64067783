"""Conversions between ROS messages and the plain values the ROS-free cores use (needs
the message packages, not an rclpy context).

alpha travels as std_msgs/Float64MultiArray with a two-dimensional layout, row-major:
``dim[0] = ("coefficient", size 6, stride 24)``, ``dim[1] = ("output", size 4, stride 4)``,
``data_offset = 0``; ``data`` is then exactly the coefficient-major 24-vector of
``rabbit_hzd_controller.alpha``. Outputs are (stance hip, stance knee, swing hip, swing knee).
Joint torques travel as a one-dimensional Float64MultiArray labelled ``joint`` in
``ACTUATED_JOINTS`` order.
"""

from __future__ import annotations

import math
from typing import Sequence

from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from .joints import ACTUATED_JOINTS, JOINT_NAMES

ALPHA_ROWS = 6
ALPHA_COLS = 4
ALPHA_DIMENSIONS = ("coefficient", "output")
TORQUE_DIMENSION = "joint"


class MessageError(ValueError):
    """A message that does not have the documented layout or contents."""


def alpha_to_msg(alpha: Sequence[float]) -> Float64MultiArray:
    """24 coefficients (coefficient-major) -> Float64MultiArray with a 6 x 4 layout."""
    values = [float(a) for a in alpha]
    if len(values) != ALPHA_ROWS * ALPHA_COLS:
        raise MessageError(f"alpha needs {ALPHA_ROWS * ALPHA_COLS} values, got {len(values)}")
    layout = MultiArrayLayout(
        dim=[
            MultiArrayDimension(label=ALPHA_DIMENSIONS[0], size=ALPHA_ROWS, stride=ALPHA_ROWS * ALPHA_COLS),
            MultiArrayDimension(label=ALPHA_DIMENSIONS[1], size=ALPHA_COLS, stride=ALPHA_COLS),
        ],
        data_offset=0,
    )
    return Float64MultiArray(layout=layout, data=values)


def alpha_from_msg(msg: Float64MultiArray) -> list[float]:
    """Float64MultiArray -> 24 coefficients; raises :class:`MessageError` on a wrong layout,
    size or non-finite value. An empty layout is accepted if ``data`` has 24 values."""
    data = list(msg.data)
    dims = list(msg.layout.dim)
    if dims:
        shape = [(d.label, d.size) for d in dims]
        expected = [(ALPHA_DIMENSIONS[0], ALPHA_ROWS), (ALPHA_DIMENSIONS[1], ALPHA_COLS)]
        if shape != expected:
            raise MessageError(f"alpha layout must be {expected}, got {shape}")
        if msg.layout.data_offset != 0:
            raise MessageError("alpha layout data_offset must be 0")
    if len(data) != ALPHA_ROWS * ALPHA_COLS:
        raise MessageError(f"alpha needs {ALPHA_ROWS * ALPHA_COLS} values, got {len(data)}")
    if not all(math.isfinite(v) for v in data):
        raise MessageError("alpha contains NaN or infinite values")
    return data


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
        return list(position), list(velocity)
    try:
        index = [names.index(n) for n in JOINT_NAMES]
    except ValueError as exc:
        raise MessageError(f"joint state lacks a joint: {exc}") from None
    return [position[i] for i in index], [velocity[i] for i in index]
