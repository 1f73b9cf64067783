#!/usr/bin/env python3
"""``rabbit_sim.commands.record`` as a script in a clone: Record the stack's topics to a rosbag2 bag (metadata.yaml + MCAP), like ``ros2 bag record``, by running ``recorder_node`` in this process until Ctrl-C / SIGTERM.

``--help`` prints its options."""

import sys

from rabbit_sim.commands.record import main

if __name__ == "__main__":
    sys.exit(main())
