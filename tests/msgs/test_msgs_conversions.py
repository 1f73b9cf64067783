"""rabbit_msgs_py: topic names, QoS and message conversions (real ROS message types)."""

import math

import pytest
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from rabbit_hzd_controller.alpha import alpha_matrix
from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.conversions import (
    MessageError,
    alpha_from_msg,
    alpha_to_msg,
    controller_id,
    joint_state_vectors,
    phase_from_msg,
    phase_to_msg,
    short,
    torques_from_msg,
    torques_to_msg,
)
from rabbit_msgs_py.joints import ACTUATED_JOINTS, JOINT_NAMES
from rabbit_policy.runtime.gait_library import GaitLibrary

pytestmark = pytest.mark.unit


def test_alpha_round_trip_and_layout():
    alpha = GaitLibrary.load().nearest(1.0).alpha
    msg = alpha_to_msg(alpha)
    assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == [("output", 4, 24), ("coefficient", 6, 6)]
    assert alpha_from_msg(msg) == list(alpha)
    # Row-major indexing per the 4 x 6 layout agrees with the core's 6 x 4 matrix.
    m = alpha_matrix(alpha)
    _, d1 = msg.layout.dim
    for j in range(4):
        for k in range(6):
            assert msg.data[msg.layout.data_offset + d1.stride * j + k] == m[k, j]


@pytest.mark.parametrize(
    "data, dims",
    [
        ([0.0] * 23, None),
        ([math.nan] + [0.0] * 23, None),
        ([0.0] * 24, [("coefficient", 6), ("output", 4)]),
        ([0.0] * 24, [("output", 6), ("coefficient", 4)]),
    ],
)
def test_malformed_alpha_is_rejected(data, dims):
    msg = Float64MultiArray(data=data)
    if dims:
        msg.layout.dim = [MultiArrayDimension(label=label, size=size, stride=size) for label, size in dims]
    with pytest.raises(MessageError):
        alpha_from_msg(msg)


def test_the_phase_round_trips_and_bad_phase_messages_are_refused():
    from builtin_interfaces.msg import Time
    from sensor_msgs.msg import JointState

    msg = phase_to_msg(0.375, 2.25, Time(sec=1, nanosec=19_000_000), "right_foot")
    assert (list(msg.name), msg.header.frame_id) == (["gait_phase"], "right_foot")
    assert phase_from_msg(msg) == (1_019_000_000, 0.375, 2.25)
    for bad in (JointState(name=["gait_phase"], position=[0.5], velocity=[]),
                JointState(name=["phase"], position=[0.5], velocity=[1.0]),
                JointState(name=["gait_phase"], position=[math.nan], velocity=[1.0])):
        with pytest.raises(MessageError):
            phase_from_msg(bad)


def test_torque_replies_round_trip_in_any_joint_order_and_reject_bad_ones():
    from builtin_interfaces.msg import Time
    from sensor_msgs.msg import JointState

    msg = torques_to_msg([1.0, -2.0, 3.5, 0.0], Time(sec=2, nanosec=5_000_000), "hzd_controller_node/abcd")
    assert list(msg.name) == list(ACTUATED_JOINTS)
    assert torques_from_msg(msg) == (2_005_000_000, "hzd_controller_node/abcd", [1.0, -2.0, 3.5, 0.0])
    shuffled = JointState(name=list(reversed(ACTUATED_JOINTS)), effort=[0.0, 3.5, -2.0, 1.0])
    assert torques_from_msg(shuffled)[2] == [1.0, -2.0, 3.5, 0.0]
    for bad in (JointState(name=["left_hip"], effort=[1.0, 2.0]),
                JointState(name=["a", "b", "c", "d"], effort=[0.0] * 4),
                JointState(name=list(ACTUATED_JOINTS), effort=[1.0, 2.0, math.inf, 0.0])):
        with pytest.raises(MessageError):
            torques_from_msg(bad)
    assert controller_id("hzd_controller_node") != controller_id("hzd_controller_node")
    assert len(short("x" * 1000)) == 120 and short([1e308]) == "[1e+308]"


def test_joint_state_any_order():
    names = list(reversed(JOINT_NAMES))
    q, dq = joint_state_vectors(names, list(range(7)), [10 + i for i in range(7)])
    assert q == [6, 5, 4, 3, 2, 1, 0]
    assert dq == [16, 15, 14, 13, 12, 11, 10]
    with pytest.raises(MessageError):
        joint_state_vectors(names[:-1], list(range(6)), list(range(6)))
    with pytest.raises(MessageError):
        joint_state_vectors(names, list(range(6)), list(range(7)))


def test_topic_names_are_relative_unique_and_resolve_in_a_namespace():
    names = [v for k, v in vars(topics).items() if k.isupper() and isinstance(v, str)]  # (SIM_MODES: values)
    assert len(names) == len(set(names)) == 27  # 24 topics, 3 services
    assert not any(n.startswith("/") for n in names)  # relative: a node's namespace applies
    assert topics.resolve(topics.ALPHA) == "/hzd/alpha" and topics.resolve(topics.CMD_SPEED) == "/cmd_speed"
    assert topics.resolve(topics.JOINT_STATES, "/rabbit2") == "/rabbit2/joint_states"
    assert topics.resolve(topics.JOINT_STATES, "/rabbit2/") == "/rabbit2/joint_states"


def test_gait_parameters_are_latched():
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    assert qos.GAIT_QOS.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert qos.GAIT_QOS.reliability == ReliabilityPolicy.RELIABLE
    assert qos.STREAM_QOS.reliability == ReliabilityPolicy.RELIABLE


def test_strict_json_writes_null_for_non_finite_numbers():
    import json
    import math

    from rabbit_msgs_py import strict_json

    text = strict_json.dumps({"a": math.nan, "b": [1.5, math.inf, (-math.inf, 2)], "c": "x"})
    assert json.loads(text) == {"a": None, "b": [1.5, None, [None, 2]], "c": "x"}
    assert "NaN" not in text and "Infinity" not in text
