"""A flood of bad messages on a topic a node subscribes to (issue 75, item 3): each refusal is
counted and at most one line a second is logged, so the node's logger is called a few times,
not once a message (rclpy's ``throttle_duration_sec`` still costs a logger call a message: a
10 kHz ``/joint_states`` flood so starved the composed loop that it made no progress, measured
with ``scripts/bench_stack.py --only flood_composed --flood-topic joint_states``). Provoked
directly: 1,500 malformed messages published at once."""

from __future__ import annotations

import math
import time

import pytest
import rclpy
from geometry_msgs.msg import Twist, TwistStamped, Vector3
from sensor_msgs.msg import JointState

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.joints import ACTUATED_JOINTS, JOINT_NAMES
from rabbit_policy.policy_node import PolicyNode
from rabbit_sim.sim_node import SimNode
from ros_helpers import ros_context, spin_for, spin_until

pytestmark = pytest.mark.ros

BURST = 1500


class CountingLogger:
    """Stands in for the node's logger during the burst: each call counted and kept, none
    written (rclpy's logger refuses one call site at two severities, and a forwarding wrapper
    would be that one site)."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def __getattr__(self, severity: str):
        return lambda text, **_kwargs: self.lines.append((severity, text))


FLOODS = {  # node (its parameters), the topic, its QoS, a message the node refuses, the kind it counts it as
    "controller /joint_states": (HZDControllerNode, {}, topics.JOINT_STATES, qos.STREAM_QOS,
                                 JointState(name=list(JOINT_NAMES), position=[math.nan] * 7, velocity=[0.0] * 7),
                                 "joint_states"),
    "simulator /joint_torques": (SimNode, {}, topics.JOINT_TORQUES, qos.TORQUE_QOS,
                                 JointState(name=list(ACTUATED_JOINTS), effort=[math.nan] * 4), "joint_torques"),
    "policy /hip_velocity": (PolicyNode, {"hip_source": "hip_velocity"}, topics.HIP_VELOCITY, qos.HIP_VELOCITY_QOS,
                             TwistStamped(twist=Twist(linear=Vector3(x=math.nan))), "hip_velocity"),
}


@pytest.mark.parametrize("flood", sorted(FLOODS))
def test_a_flood_of_refused_messages_is_counted_and_logged_once_a_second(flood):
    node_class, params, topic, profile, message, kind = FLOODS[flood]
    with ros_context() as (context, executor):
        node = node_class(context=context, solo_check=0.0, **params)
        logger = CountingLogger()
        rejections = node.core.rejections if isinstance(node, PolicyNode) else node._rejections
        flooder = rclpy.create_node("flooder", context=context)
        for n in (node, flooder):
            executor.add_node(n)
        publisher = flooder.create_publisher(type(message), topic, profile)
        assert spin_until(executor, lambda: publisher.get_subscription_count() >= 1)
        spin_for(executor, 0.2)  # the start-up lines
        node.get_logger = lambda: logger
        for i in range(BURST):  # as fast as this process publishes, the node taking them in between
            publisher.publish(message)
            if i % 5 == 4:
                executor.spin_once(timeout_sec=0.0)
        spin_for(executor, 0.5)
        refused = rejections.counts.get(kind, 0)
    # refused (a reader's KEEP_LAST may drop some before they are taken), each counted, and logged
    # once a second at most: the logger called a few times, not once a refusal
    assert 100 <= refused <= BURST and len(logger.lines) <= 3, (refused, logger.lines[:5])


def test_a_drained_subscription_takes_a_burst_in_one_executor_callback():
    """``rabbit_msgs_py.polled.subscribe_drained`` (every input a stranger can flood): 300
    messages waiting are all handed on, in order, by the first executor callback, so a flood
    costs the executor one callback a burst, not one a message."""
    from std_msgs.msg import Float64

    from rabbit_msgs_py.polled import subscribe_drained

    with ros_context() as (context, executor):
        reader, writer = (rclpy.create_node(name, context=context) for name in ("reader", "writer"))
        taken: list[float] = []
        subscribe_drained(reader, Float64, "burst", lambda msg: taken.append(msg.data), qos._reliable(1000))
        publisher = writer.create_publisher(Float64, "burst", qos._reliable(1000))
        for n in (reader, writer):
            executor.add_node(n)
        assert spin_until(executor, lambda: publisher.get_subscription_count() >= 1)
        for i in range(300):
            publisher.publish(Float64(data=float(i)))
        time.sleep(0.3)  # delivered into the reader, none taken
        deadline = time.monotonic() + 5.0
        while not taken and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
    assert taken == [float(i) for i in range(len(taken))] and len(taken) >= 250, len(taken)
