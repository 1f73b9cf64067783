"""Publish a desired walking speed on /cmd_speed (std_msgs/Float64), for users without the
``ros2`` command line, or who want it delivered: like

    ros2 topic pub --once /cmd_speed std_msgs/msg/Float64 "{data: 1.2}"

but waiting for the subscriber first (``--once`` can publish before it is matched, and the
command is lost).

Usage: scripts/set_speed.py 1.2 [--wait 5] [--namespace rabbit2]
Waits (up to ``--wait`` s) until a subscriber (the policy node) is connected, publishes
once and waits for delivery. Exit status: 0 delivered, 1 nobody listening, 2 bad value.
The policy node clamps speeds outside 0.7..1.5 m/s (with a warning) and rejects NaN/inf.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from rabbit_msgs_py.cli import ArgumentParser
from rabbit_msgs_py.environment import ensure_localhost_discovery


def main(argv: list[str] | None = None) -> int:
    ensure_localhost_discovery()
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("speed", type=float, help="desired forward speed (m/s)")
    parser.add_argument("--wait", type=float, default=5.0, help="seconds to wait for a subscriber")
    parser.add_argument("--namespace", default="", help="the stack's namespace (run_stack.py --namespace)")
    args = parser.parse_args(argv)
    if not math.isfinite(args.speed):
        parser.error("speed must be a finite number (m/s)")
    from rabbit_policy.bringup.config import valid_namespace

    try:
        namespace = valid_namespace(args.namespace) or "/"
    except ValueError as exc:
        parser.error(str(exc))

    import rclpy
    from std_msgs.msg import Float64

    from rabbit_msgs_py import qos, topics

    rclpy.init()
    node = rclpy.create_node("set_speed", namespace=namespace)
    topic = topics.resolve(topics.CMD_SPEED, namespace)
    try:
        pub = node.create_publisher(Float64, topics.CMD_SPEED, qos.COMMAND_QOS)
        deadline = time.monotonic() + args.wait
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
        if pub.get_subscription_count() == 0:
            print(f"error: nobody subscribes to {topic} (is policy_node running?)", file=sys.stderr)
            return 1
        pub.publish(Float64(data=args.speed))
        pub.wait_for_all_acked(rclpy.duration.Duration(seconds=2.0))
        print(f"{topic} <- {args.speed:.3f} m/s")
        return 0
    finally:
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    sys.exit(main())
