#!/usr/bin/env python3
"""Publish a desired walking speed on /cmd_speed (std_msgs/Float64), for users without the
``ros2`` command line. Equivalent to

    ros2 topic pub --once /cmd_speed std_msgs/msg/Float64 "{data: 1.2}"

Usage: scripts/set_speed.py 1.2 [--wait 5] [--namespace rabbit2]
Waits (up to ``--wait`` s) until a subscriber (the policy node) is connected, publishes
once and waits for delivery. Exit status: 0 delivered, 1 nobody listening, 2 bad value.
The policy node clamps speeds outside 0.7..1.5 m/s (with a warning) and rejects NaN/inf.
"""

import sys

from rabbit_policy.commands.set_speed import main

if __name__ == "__main__":
    sys.exit(main())
