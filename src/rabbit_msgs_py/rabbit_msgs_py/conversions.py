"""Conversions between ROS messages and the plain values the ROS-free cores use (needs
the message packages, not an rclpy context).

alpha travels as std_msgs/Float64MultiArray holding a 4 x 6 matrix, row-major:
``dim[0] = ("output", size 4, stride 24)``, ``dim[1] = ("coefficient", size 6, stride 6)``,
``data_offset = 0``; so ``data[6 j + k]`` is Bezier coefficient k (0..5) of output j, and
the outputs are (stance hip, stance knee, swing hip, swing knee), rad. The ROS-free core
keeps the paper's coefficient-major 24-vector (``flat[4 k + j]``, see
``rabbit_hzd_controller.alpha``); these functions transpose between the two.
Joint torques travel as a *reply*: a sensor_msgs/JointState naming the four
``ACTUATED_JOINTS`` with their torques in ``effort`` (N m), ``header.stamp`` = the stamp of
the ``/joint_states`` message they answer and ``header.frame_id`` = the id of the
controller instance that computed them (:func:`controller_id`). The simulator applies a
reply only to the state it answers and only from the one controller it is paired with.
A state batch (``/sim/state_batch``) is a Float64MultiArray of ``n`` rows of
:data:`BATCH_FIELDS` (``dim[0] = ("state", n, 22 n)``, ``dim[1] = ("stamp_ns,position[7],velocity[7],effort[7]",
22, 22)``): each row one state as ``/joint_states`` sends it, the stamp as integer ns of sim time.
"""

from __future__ import annotations

import array
import math
import os
import sys
from typing import Callable, NamedTuple, Sequence

from builtin_interfaces.msg import Time
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from .cdr import CdrError, read_float64_multi_array, read_joint_state
from .joints import ACTUATED_JOINTS, JOINT_NAMES, N_JOINTS
from .node_runner import one_line

ALPHA_OUTPUTS = 4
ALPHA_COEFFICIENTS = 6
ALPHA_SIZE = ALPHA_OUTPUTS * ALPHA_COEFFICIENTS
ALPHA_DIMENSIONS = ("output", "coefficient")


class MessageError(ValueError):
    """A message that does not have the documented layout or contents."""


SIGNATURE_LABEL = "signature "
"""A signed gait's third layout dimension (size 1) is labelled with this, then the
signature (``rabbit_msgs_py.pairing``: the policy instance, its gait count, Kd and the tag)."""


def alpha_to_msg(alpha: Sequence[float], signature: str = "") -> Float64MultiArray:
    """24 coefficients (core order, coefficient-major) -> Float64MultiArray, 4 x 6 layout;
    with a ``signature`` a third dimension of size 1 carries it (4 x 6 x 1: the same data)."""
    values = [float(a) for a in alpha]
    if len(values) != ALPHA_SIZE:
        raise MessageError(f"alpha needs {ALPHA_SIZE} values, got {len(values)}")
    dims = [MultiArrayDimension(label=ALPHA_DIMENSIONS[0], size=ALPHA_OUTPUTS, stride=ALPHA_SIZE),
            MultiArrayDimension(label=ALPHA_DIMENSIONS[1], size=ALPHA_COEFFICIENTS, stride=ALPHA_COEFFICIENTS)]
    if signature:
        dims.append(MultiArrayDimension(label=SIGNATURE_LABEL + signature, size=1, stride=1))
    layout = MultiArrayLayout(dim=dims, data_offset=0)
    data = [values[ALPHA_OUTPUTS * k + j] for j in range(ALPHA_OUTPUTS) for k in range(ALPHA_COEFFICIENTS)]
    return Float64MultiArray(layout=layout, data=data)


def alpha_from_msg(msg: Float64MultiArray) -> list[float]:
    """Float64MultiArray (4 x 6 layout) -> 24 coefficients in core order; raises
    :class:`MessageError` on a wrong layout, size or non-finite value. An empty layout is
    accepted if ``data`` has 24 values (then read as the documented 4 x 6 order)."""
    data = list(msg.data)
    dims = list(msg.layout.dim)
    if len(dims) == 3 and dims[2].label.startswith(SIGNATURE_LABEL) and dims[2].size == 1:
        dims = dims[:2]  # a signed gait (alpha_signature reads it)
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


def alpha_signature(msg: Float64MultiArray) -> str:
    """The signature a gait carries (:func:`alpha_to_msg`), '' if none."""
    dims = list(msg.layout.dim)
    if len(dims) == 3 and dims[2].label.startswith(SIGNATURE_LABEL):
        return dims[2].label[len(SIGNATURE_LABEL):]
    return ""


_THREE_DIMENSIONS = (3).to_bytes(4, "little")
"""The bytes after a signed gait's CDR header: its three dimensions' count."""


def may_carry_gait_signature(raw: bytes) -> bool:
    """False when a gait's serialized bytes (a raw ``/hzd/alpha`` message) cannot carry a
    signature (:func:`alpha_to_msg`: a third dimension labelled ``SIGNATURE_LABEL``): a keyed
    controller refuses it before it is deserialized, so a flood of unsigned gaits costs it a
    few bytes compared a message."""
    return raw[4:8] == _THREE_DIMENSIONS and SIGNATURE_LABEL.encode() in raw


def controller_id(node_name: str) -> str:
    """A fresh id for one controller instance, ``<node name>/<8 hex digits>``: what it
    writes in the ``frame_id`` of its torque replies (a restarted controller is another)."""
    return f"{node_name}/{os.urandom(4).hex()}"


def torques_to_msg(torques: Sequence[float], answers: Time | None = None, source: str = "") -> JointState:
    """4 joint torques (N m, ``ACTUATED_JOINTS`` order) -> the reply to the state stamped
    ``answers``, from controller ``source``."""
    values = [float(t) for t in torques]
    if len(values) != len(ACTUATED_JOINTS):
        raise MessageError(f"expected {len(ACTUATED_JOINTS)} torques, got {len(values)}")
    msg = JointState(name=list(ACTUATED_JOINTS), effort=values)
    if answers is not None:
        msg.header.stamp = answers
    msg.header.frame_id = source
    return msg


def torques_from_msg(msg: JointState) -> tuple[int, str, list[float]]:
    """A torque reply -> (stamp answered in ns, controller id, 4 torques in
    ``ACTUATED_JOINTS`` order, whatever order the message names them in); raises
    :class:`MessageError` if malformed."""
    return torques_from_fields(stamp_to_ns(msg.header.stamp), msg.header.frame_id, msg.name, msg.effort)


def torques_from_bytes(data: bytes) -> tuple[int, str, list[float]]:
    """:func:`torques_from_msg` of a reply as its serialized bytes (``rabbit_msgs_py.cdr``)."""
    try:
        stamp, frame_id, names, _position, _velocity, effort = read_joint_state(data)
    except CdrError as exc:
        raise MessageError(str(exc)) from None
    return torques_from_fields(stamp, frame_id, names, effort)


def torques_from_fields(stamp: int, frame_id: str, names: Sequence[str], effort: Sequence[float]
                        ) -> tuple[int, str, list[float]]:
    """The checks of :func:`torques_from_msg` on the reply's fields (stamp in ns)."""
    names, effort = list(names), list(effort)
    if len(effort) != len(names):
        raise MessageError(f"torque reply needs one effort per name, got {len(names)} names and {len(effort)} efforts")
    if tuple(names) == ACTUATED_JOINTS:
        data = effort
    else:
        try:
            data = [effort[names.index(n)] for n in ACTUATED_JOINTS]
        except ValueError as exc:
            raise MessageError(f"torque reply lacks a joint ({exc}); expected {list(ACTUATED_JOINTS)}") from None
    if not all(math.isfinite(v) for v in data):
        raise MessageError("torques contain NaN or infinite values")
    return stamp, frame_id, data


PHASE_JOINT = "gait_phase"


def phase_to_msg(tau: float, tau_rate: float, stamp: Time, stance_foot: str) -> JointState:
    """The controller's gait phase ``tau`` (1) and its rate (1/s) on the state stamped
    ``stamp`` -> ``/hzd/phase`` (one joint ``gait_phase``; ``frame_id`` the stance foot)."""
    msg = JointState(name=[PHASE_JOINT], position=[float(tau)], velocity=[float(tau_rate)])
    msg.header.stamp = stamp
    msg.header.frame_id = stance_foot
    return msg


def phase_from_msg(msg: JointState) -> tuple[int, float, float]:
    """``/hzd/phase`` -> (stamp of the state in ns, tau, d tau/dt in 1/s); raises
    :class:`MessageError` if malformed."""
    if list(msg.name) != [PHASE_JOINT] or len(msg.position) != 1 or len(msg.velocity) != 1:
        raise MessageError(f"a phase message names one joint {PHASE_JOINT!r} with one position and one velocity, "
                           f"got names {short(list(msg.name), 60)}")
    tau, rate = float(msg.position[0]), float(msg.velocity[0])
    if not (math.isfinite(tau) and math.isfinite(rate)):
        raise MessageError("phase contains NaN or infinite values")
    return stamp_to_ns(msg.header.stamp), tau, rate


def short(value: object, limit: int = 120) -> str:
    """A string as it is, anything else as ``repr``, on one line cut to ``limit`` characters:
    for log messages about bad input (:func:`rabbit_msgs_py.node_runner.one_line`)."""
    return one_line(value if isinstance(value, str) else repr(value), limit)


def joint_state_from_bytes(data: bytes) -> tuple[int, str, list[float], list[float]]:
    """A serialized JointState (``rabbit_msgs_py.cdr``) -> (stamp ns, frame_id, q, dq) in
    ``JOINT_NAMES`` order, checked as :func:`joint_state_vectors` checks them;
    :class:`MessageError` otherwise."""
    try:
        stamp, frame_id, names, position, velocity, _effort = read_joint_state(data)
    except CdrError as exc:
        raise MessageError(str(exc)) from None
    return (stamp, frame_id, *joint_state_vectors(names, position, velocity))


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


BATCH_FIELDS = 1 + 3 * N_JOINTS
"""Values per state in a state batch: the stamp (ns), then position, velocity and effort of
the 7 joints (``JOINT_NAMES`` order; m, rad, m/s, rad/s, N m)."""
BATCH_DIMENSIONS = ("state", "stamp_ns,position[7],velocity[7],effort[7]")
MAX_BATCH_STAMP = 2 ** 53
"""ns: stamps up to here (104 days of sim time) are exact in a float64."""


class BatchState(NamedTuple):
    """One row of a state batch: stamp (ns of sim time), and the 7 joints' positions,
    velocities and efforts (``JOINT_NAMES`` order)."""

    stamp: int
    position: Sequence[float]
    velocity: Sequence[float]
    effort: Sequence[float]


def state_batch_to_msg(rows: array.array, count: int, label: str = BATCH_DIMENSIONS[0]) -> Float64MultiArray:
    """``count`` states, :data:`BATCH_FIELDS` values each (``rows``: float64, row after row)
    -> the ``/sim/state_batch`` message (layout in the module docstring); ``label``: its first
    dimension's (``state``, or signed: ``PairingKey.batch_label``)."""
    layout = MultiArrayLayout(dim=[
        MultiArrayDimension(label=label, size=count, stride=count * BATCH_FIELDS),
        MultiArrayDimension(label=BATCH_DIMENSIONS[1], size=BATCH_FIELDS, stride=BATCH_FIELDS)], data_offset=0)
    return Float64MultiArray(layout=layout, data=rows)


def state_batch_from_msg(msg: Float64MultiArray) -> list[BatchState]:
    """A ``/sim/state_batch`` message -> its states, oldest first; raises
    :class:`MessageError` on a wrong layout, a stamp that is not a whole number of ns in
    [0, 2^53], or a value that is not finite."""
    dims = [(d.label, d.size) for d in msg.layout.dim]
    _check_batch_layout(dims, msg.layout.data_offset, len(msg.data))
    return _batch_states(msg.data)


def _check_batch_layout(dims: list[tuple[str, int]], data_offset: int, values: int) -> None:
    """:class:`MessageError` unless (label, size) ``dims`` and ``data_offset`` are a state
    batch's for ``values`` values (a signature may follow the first label after a space)."""
    count = values // BATCH_FIELDS
    if [(label.partition(" ")[0], size) for label, size in dims] != [(BATCH_DIMENSIONS[0], count),
                                                                    (BATCH_DIMENSIONS[1], BATCH_FIELDS)] \
            or data_offset != 0 or values != count * BATCH_FIELDS:
        raise MessageError(f"a state batch is n x {BATCH_FIELDS} values labelled {list(BATCH_DIMENSIONS)}, got "
                           f"{values} values in {short(dims, 100)}")


def _batch_states(data: Sequence[float]) -> list[BatchState]:
    """A state batch's values (laid out as checked) -> its states, or :class:`MessageError`."""
    if not all(math.isfinite(v) for v in data):
        raise MessageError("state batch contains NaN or infinite values")
    states = []
    j = N_JOINTS
    for i in range(0, len(data), BATCH_FIELDS):
        stamp = data[i]
        if not (0.0 <= stamp <= MAX_BATCH_STAMP and stamp == int(stamp)):
            raise MessageError(f"a state batch stamp is a whole number of ns in [0, 2^53], got {stamp!r}")
        states.append(BatchState(int(stamp), data[i + 1:i + 1 + j], data[i + 1 + j:i + 1 + 2 * j],
                                 data[i + 1 + 2 * j:i + 1 + 3 * j]))
    return states


_TWO_DIMENSIONS = (2).to_bytes(4, "little")
"""The bytes after a state batch's CDR header: its two dimensions' count (its first label's
length and text follow, ``rabbit_msgs_py.cdr``)."""


def batch_states_or_log(raw: bytes, topic: str, error: Callable[[str], None],
                        verify: Callable[[str, bytes], None] | None = None) -> list[BatchState]:
    """The states of a ``/sim/state_batch`` message as its serialized bytes (a raw
    subscription's: :func:`~rabbit_msgs_py.cdr.read_float64_multi_array`) from ``topic`` (its
    full name); for a malformed one, or one ``verify`` refuses (called with the first
    dimension's label and the values as float64 bytes, raising ``ValueError``:
    ``pairing.SignedBatches``), none, and one line to ``error`` (the node's logger,
    throttled). The layout and the signature are checked on the bytes before any value is
    converted, so a refused message costs a few microseconds (a flood's, docs/faults.md)."""
    if raw[4:8] != _TWO_DIMENSIONS or raw[12:17] != b"state":  # a flood's usual message: refused first, cheapest
        error(f"ignoring {topic}: not a state batch (its bytes do not start with two dimensions, the first "
              f"labelled {BATCH_DIMENSIONS[0]!r})")
        return []
    try:
        dims, data_offset, values = read_float64_multi_array(raw)
        _check_batch_layout([(label, size) for label, size, _stride in dims], data_offset, len(values) // 8)
        data = array.array("d", values)
        if sys.byteorder == "big":  # the wire's values are little-endian, a signature's native
            data.byteswap()
        if verify is not None:
            verify(dims[0][0], data.tobytes())
        return _batch_states(data)
    except (CdrError, MessageError, ValueError) as exc:
        error(f"ignoring {topic}: {exc}")
        return []


def stamp_to_ns(stamp) -> int:
    """builtin_interfaces/Time (``sec``, ``nanosec``) -> integer nanoseconds."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def stamp_from_ns(ns: int) -> Time:
    """Integer nanoseconds -> builtin_interfaces/Time."""
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_to_seconds(stamp) -> float:
    """builtin_interfaces/Time -> seconds (float)."""
    return stamp.sec + stamp.nanosec * 1e-9
