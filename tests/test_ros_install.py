"""The ROS 2 Jazzy wheels from PyPI work in .venv: a publisher and a subscriber talk through
Fast DDS in one process, discovery limited to localhost (set in conftest.py)."""

import os

import pytest

import rclpy

pytestmark = pytest.mark.ros


def test_discovery_is_limited_to_localhost():
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert 0 <= int(os.environ["ROS_DOMAIN_ID"]) <= 101


def test_in_process_publish_subscribe():
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Float64

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("rabbit_install_check", context=context)
        received = []
        node.create_subscription(Float64, "install_check", lambda m: received.append(m.data), 10)
        pub = node.create_publisher(Float64, "install_check", 10)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        for i in range(200):
            pub.publish(Float64(data=float(i)))
            executor.spin_once(timeout_sec=0.01)
            if received:
                break
        assert received and received[0] >= 0.0
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
