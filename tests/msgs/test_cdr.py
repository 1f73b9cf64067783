"""The 1 kHz streams' JointState bytes (rabbit_msgs_py.cdr) are what rclpy writes and reads:
random messages round-trip against rclpy's own serialization both ways, and bytes that are
not a JointState are refused with one line. The state batch's Float64MultiArray is read from
rclpy's bytes alike."""

from __future__ import annotations

import random

import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from rabbit_msgs_py.cdr import CdrError, JointStateWriter, read_float64_multi_array, read_joint_state
from rabbit_msgs_py.conversions import MessageError, joint_state_from_bytes, torques_from_bytes
from rabbit_msgs_py.joints import ACTUATED_JOINTS, JOINT_NAMES

pytestmark = pytest.mark.unit


def _random_message(rng: random.Random) -> tuple[JointState, tuple]:
    names = ["".join(rng.choice("abxyz_é") for _ in range(rng.randint(0, 9))) for _ in range(rng.randint(0, 7))]
    arrays = [[rng.uniform(-1e3, 1e3) for _ in range(rng.choice([0, len(names), rng.randint(0, 9)]))]
              for _ in range(3)]
    frame = "".join(rng.choice("abc/:0123") for _ in range(rng.randint(0, 30)))
    stamp = rng.randint(0, 10 ** 12)
    msg = JointState(name=names, position=arrays[0], velocity=arrays[1], effort=arrays[2])
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = stamp // 10 ** 9, stamp % 10 ** 9, frame
    return msg, (stamp, frame, names, *(tuple(a) for a in arrays))


def test_joint_state_bytes_round_trip_against_rclpys_serialization():
    rng = random.Random(7)
    for _ in range(300):
        msg, fields = _random_message(rng)
        assert read_joint_state(serialize_message(msg)) == fields  # what any publisher sends, read
        ours = JointStateWriter(fields[2]).bytes(fields[0], fields[1], *fields[3:])
        back = deserialize_message(ours, JointState)  # what we send, as any subscriber reads it
        assert (back.header.stamp.sec * 10 ** 9 + back.header.stamp.nanosec, back.header.frame_id, list(back.name),
                tuple(back.position), tuple(back.velocity), tuple(back.effort)) == fields


def test_bytes_that_are_not_a_joint_state_are_refused_in_one_line():
    good = JointStateWriter(JOINT_NAMES).bytes(5_000_000, "", [0.1] * 7, [0.2] * 7, [0.0] * 7)
    assert joint_state_from_bytes(good) == (5_000_000, "", [0.1] * 7, [0.2] * 7)
    for bad in (good[:30], good[:-8], b"\x01\x00\x00\x00" + good[4:], b"", good[:12] + b"\xff\xff\xff\x7f"):
        with pytest.raises((CdrError, MessageError)):
            read_joint_state(bad)
        with pytest.raises(MessageError):
            joint_state_from_bytes(bad)
    reply = JointStateWriter(ACTUATED_JOINTS).bytes(7_000_000, "hzd_controller_node/ab", (), (), [1.0, 2.0, 3.0, 4.0])
    assert torques_from_bytes(reply) == (7_000_000, "hzd_controller_node/ab", [1.0, 2.0, 3.0, 4.0])
    nan = JointStateWriter(ACTUATED_JOINTS).bytes(7_000_000, "x", (), (), [1.0, float("nan"), 3.0, 4.0])
    with pytest.raises(MessageError, match="NaN"):
        torques_from_bytes(nan)


def test_float64_multi_array_bytes_read_as_rclpy_wrote_them_and_others_refused():
    rng = random.Random(11)
    for _ in range(300):
        dims = [("".join(rng.choice("ab é=:") for _ in range(rng.randint(0, 40))), rng.randint(0, 2 ** 32 - 1),
                 rng.randint(0, 2 ** 32 - 1)) for _ in range(rng.randint(0, 3))]
        values = [rng.uniform(-1e9, 1e9) for _ in range(rng.choice([0, 1, 22, rng.randint(0, 70)]))]
        msg = Float64MultiArray(data=values)
        msg.layout.dim = [MultiArrayDimension(label=label, size=size, stride=stride) for label, size, stride in dims]
        msg.layout.data_offset = rng.randint(0, 9)
        raw = serialize_message(msg)
        read, offset, data = read_float64_multi_array(raw)
        assert (read, offset, data) == (dims, msg.layout.data_offset, msg.data.tobytes())
        for bad in (raw[:-9], raw[:7], b"\x00\x00" + raw[2:], raw + bytes(8)):
            with pytest.raises(CdrError):
                read_float64_multi_array(bad)
