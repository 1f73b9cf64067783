"""sensor_msgs/JointState as the bytes on the wire (CDR, little endian, as rmw_fastrtps
writes and reads them), for the two 1 kHz streams: a node publishes these bytes and takes
the bytes it subscribes to (rclpy's serialized publish and take), so no Python message
object is built or converted per tick. Every other node sees an ordinary JointState.
std_msgs/Float64MultiArray is read the same way (:func:`read_float64_multi_array`) for
``/sim/state_batch``: its observers check a batch's layout and signature on the bytes, so a
flood of messages they refuse costs no message object either.

Layout: the 4-byte encapsulation header (``00 01 00 00``), then the fields in order, each
primitive aligned to its size counted from the end of that header: ``header.stamp`` (int32
sec, uint32 nanosec), ``header.frame_id`` and each ``name`` as a uint32 length (with the
terminating NUL) and the UTF-8 bytes and a NUL, then ``position``, ``velocity``, ``effort``
each as a uint32 count and that many float64.
"""

from __future__ import annotations

import struct
from typing import Sequence

ENCAPSULATION = b"\x00\x01\x00\x00"
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")


class CdrError(ValueError):
    """Bytes that are not a JointState."""


def _string(text: str) -> bytes:
    raw = text.encode() + b"\x00"
    return _U32.pack(len(raw)) + raw + b"\x00" * (-len(raw) % 4)


class JointStateWriter:
    """The bytes of JointState messages naming ``names`` (fixed for the writer)."""

    def __init__(self, names: Sequence[str]) -> None:
        self._names = _U32.pack(len(names)) + b"".join(_string(n) for n in names)  # 4-aligned wherever it starts

    def bytes(self, stamp_ns: int, frame_id: str, position: Sequence[float], velocity: Sequence[float],
              effort: Sequence[float]) -> bytes:
        """One message: the stamp (ns), ``frame_id`` and the three arrays (any may be empty)."""
        parts = [ENCAPSULATION, _STAMP.pack(stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000),
                 _string(frame_id), self._names]
        size = sum(map(len, parts)) - 4
        for values in (position, velocity, effort):
            n = len(values)
            head = _U32.pack(n)
            size += 4
            if n:
                pad = -size % 8
                head += b"\x00" * pad
                size += pad + 8 * n
                parts.append(head + struct.pack(f"<{n}d", *values))
            else:
                parts.append(head)
        return b"".join(parts)


def _read_string(data: bytes, at: int) -> tuple[str, int]:
    (n,) = _U32.unpack_from(data, at)
    end = at + 4 + n
    if n < 1 or end > len(data) or data[end - 1] != 0:
        raise CdrError("a string runs past the message or has no terminating NUL")
    return data[at + 4:end - 1].decode(), end + (-(end - 4) % 4)


def read_joint_state(data: bytes) -> tuple[int, str, list[str], tuple[float, ...], tuple[float, ...],
                                           tuple[float, ...]]:
    """JointState bytes -> (stamp ns, frame_id, names, position, velocity, effort);
    :class:`CdrError` for bytes that are not one (truncated, another encoding)."""
    if data[:2] != ENCAPSULATION[:2]:
        raise CdrError(f"not little-endian CDR (encapsulation {bytes(data[:4]).hex()})")
    try:
        sec, nanosec = _STAMP.unpack_from(data, 4)
        frame_id, at = _read_string(data, 12)
        (count,) = _U32.unpack_from(data, at)
        at += 4
        if count > len(data):
            raise CdrError("more names than bytes")
        names = []
        for _ in range(count):
            name, at = _read_string(data, at)
            names.append(name)
        arrays = []
        for _ in range(3):
            at += -(at - 4) % 4
            (n,) = _U32.unpack_from(data, at)
            at += 4
            if n:
                at += -(at - 4) % 8
                if at + 8 * n > len(data):
                    raise CdrError("an array runs past the message")
                arrays.append(struct.unpack_from(f"<{n}d", data, at))
                at += 8 * n
            else:
                arrays.append(())
    except (struct.error, UnicodeDecodeError) as exc:
        raise CdrError(f"not a JointState: {exc}") from None
    return sec * 1_000_000_000 + nanosec, frame_id, names, arrays[0], arrays[1], arrays[2]


_DIM = struct.Struct("<II")


def read_float64_multi_array(data: bytes) -> tuple[list[tuple[str, int, int]], int, bytes]:
    """Float64MultiArray bytes -> (its dimensions as (label, size, stride), data_offset, its
    values as little-endian float64 bytes, 8 a value); :class:`CdrError` for bytes that are not
    one (truncated, another encoding). The values are not converted: a caller checks the
    layout (and a signature on these bytes) first."""
    if data[:2] != ENCAPSULATION[:2]:
        raise CdrError(f"not little-endian CDR (encapsulation {bytes(data[:4]).hex()})")
    try:
        (count,) = _U32.unpack_from(data, 4)
        if count > len(data):
            raise CdrError("more dimensions than bytes")
        at, dims = 8, []
        for _ in range(count):
            label, at = _read_string(data, at)
            size, stride = _DIM.unpack_from(data, at)
            dims.append((label, size, stride))
            at += 8
        offset, n = _DIM.unpack_from(data, at)
        at += 8
        if n:
            at += -(at - 4) % 8
        if not 0 <= len(data) - (at + 8 * n) < 8:  # the serializer may pad the end
            raise CdrError(f"{n} values do not fill the {len(data) - at} bytes after the layout")
    except (struct.error, UnicodeDecodeError) as exc:
        raise CdrError(f"not a Float64MultiArray: {exc}") from None
    return dims, offset, bytes(data[at:at + 8 * n])
