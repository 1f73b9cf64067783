"""Every topic of the stack with its message type and QoS (needs rclpy): what the
recorder subscribes to by default and writes into the bag's metadata (all but the
recorder's own ``/recorder/recorded_until``)."""

from __future__ import annotations

from dataclasses import dataclass

from geometry_msgs.msg import Twist, TwistStamped, Wrench, WrenchStamped
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, Float64MultiArray, Header, String, UInt32
from visualization_msgs.msg import MarkerArray

from . import qos, topics


@dataclass(frozen=True)
class TopicSpec:
    """A topic: name, message class, the QoS its publisher offers."""

    name: str
    msg_class: type
    qos: QoSProfile

    @property
    def type_name(self) -> str:
        """ROS 2 type string, e.g. ``sensor_msgs/msg/JointState``."""
        return type_name(self.msg_class)


def type_name(msg_class: type) -> str:
    """``sensor_msgs.msg.JointState`` -> ``sensor_msgs/msg/JointState``."""
    return f"{msg_class.__module__.split('.')[0]}/msg/{msg_class.__name__}"


STACK_TOPICS: dict[str, TopicSpec] = {
    spec.name: spec
    for spec in (
        TopicSpec(topics.JOINT_STATES, JointState, qos.STREAM_QOS),
        TopicSpec(topics.HIP_VELOCITY, TwistStamped, qos.HIP_VELOCITY_QOS),
        TopicSpec(topics.STATE_BATCH, Float64MultiArray, qos.BATCH_QOS),
        TopicSpec(topics.CLOCK, Clock, qos.CLOCK_QOS),
        TopicSpec(topics.FALLEN, Bool, qos.STATUS_QOS),
        TopicSpec(topics.JOINT_TORQUES, JointState, qos.TORQUE_QOS),
        TopicSpec(topics.STEP, Header, qos.STEP_QOS),
        TopicSpec(topics.PHASE, JointState, qos.STREAM_QOS),
        TopicSpec(topics.REFERENCE, JointState, qos.STREAM_QOS),
        TopicSpec(topics.TRACKING_ERROR, JointState, qos.STREAM_QOS),
        TopicSpec(topics.ALPHA, Float64MultiArray, qos.GAIT_QOS),
        TopicSpec(topics.KD, Float64, qos.GAIT_QOS),
        TopicSpec(topics.GAIT_TIMING, String, qos.GAIT_QOS),
        TopicSpec(topics.DECISIONS_LOST, UInt32, qos.STATUS_QOS),
        TopicSpec(topics.CMD_SPEED, Float64, qos.COMMAND_QOS),
        TopicSpec(topics.CMD_VEL, Twist, qos.COMMAND_QOS),
        TopicSpec(topics.PUSH, Wrench, qos.COMMAND_QOS),
        TopicSpec(topics.PUSH_APPLIED, WrenchStamped, qos.EVENT_QOS),
        TopicSpec(topics.INITIAL_STATE, JointState, qos.GAIT_QOS),
        TopicSpec(topics.RESETS, UInt32, qos.STATUS_QOS),
        TopicSpec(topics.MARKERS, MarkerArray, qos.MARKERS_QOS),
        TopicSpec(topics.ROBOT_DESCRIPTION, String, qos.STATUS_QOS),
        TopicSpec(topics.SIM_MODE, String, qos.STATUS_QOS),
    )
}
