"""run_stack's report follows the commands the robot walked (issue 73): one sent live on
``/cmd_speed`` during the run (``set_speed.py``, ``ros2 topic pub``) becomes a segment of its own,
dated at the state the supervisor had when it came."""

from __future__ import annotations

import pytest

from rabbit_msgs_py import qos, topics
from rabbit_policy.bringup.config import StackConfig
from rabbit_policy.bringup.in_process import run_in_process

pytestmark = [pytest.mark.ros, pytest.mark.slow]


class LiveCommand:
    """A user's node: 1.3 m/s on /cmd_speed once, on the first state batch past 1.0 s of sim time."""

    def __init__(self, context) -> None:
        import rclpy
        from std_msgs.msg import Float64, Float64MultiArray

        self.node = rclpy.create_node("user", context=context)
        self._pub = self.node.create_publisher(Float64, topics.CMD_SPEED, qos.COMMAND_QOS)
        self.node.create_subscription(Float64MultiArray, topics.STATE_BATCH, self._on_batch, qos.BATCH_QOS)
        self.sent_at: float | None = None

    def _on_batch(self, msg) -> None:
        from std_msgs.msg import Float64

        if self.sent_at is None and msg.data and msg.data[0] > 1.0e9:
            self.sent_at = msg.data[0] / 1e9
            self._pub.publish(Float64(data=1.3))


def test_a_command_sent_live_is_a_segment_of_the_report():
    made = []

    def factory(context):
        made.append(LiveCommand(context))
        return made[-1].node

    report, _nodes = run_in_process(StackConfig(duration=6.0, schedule=((0.0, 1.0),)), observers=[factory])
    segments = report.summary()["segments"]
    assert [s["command"] for s in segments] == [1.0, 1.3], segments
    assert made[0].sent_at <= segments[1]["start"] <= made[0].sent_at + 0.5
    assert segments[1]["mean_speed"] is not None and report.completed
