#!/usr/bin/env python3
"""Record the stack's topics to a rosbag2 bag (metadata.yaml + MCAP), like ``ros2 bag record``,
by running ``recorder_node`` in this process until Ctrl-C / SIGTERM.

    scripts/record.py runs/walk1                     # every stack topic
    scripts/record.py runs/walk1 --topics /joint_states /joint_torques --compression zstd
    scripts/record.py runs/walk1 --log-time sim --overwrite

Equivalent to ``ros2 run rabbit_sim recorder_node --ros-args -p output:=runs/walk1 ...``.
Exit status: 0 bag closed cleanly, 1 the bag could not be created (exists, bad path).
"""

from __future__ import annotations

import argparse
import sys

from rabbit_msgs_py.cli import ArgumentParser
from rabbit_msgs_py.environment import ensure_localhost_discovery


def main(argv: list[str] | None = None) -> int:
    ensure_localhost_discovery()
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("output", help="bag directory to create")
    parser.add_argument("--topics", nargs="+", default=[], help="topics to record (default: all stack topics)")
    parser.add_argument("--compression", choices=("none", "zstd"), default="none")
    parser.add_argument("--log-time", choices=("receive", "sim"), default="receive",
                        help="message log time: wall-clock reception (default) or sim time from /clock")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing output directory")
    args = parser.parse_args(argv)

    from rabbit_sim.recorder_node import main as recorder_main

    topics = "[" + ",".join(f"'{t}'" for t in args.topics) + "]" if args.topics else "['']"
    ros_args = ["--ros-args", "-p", f"output:={args.output}", "-p", f"topics:={topics}",
                "-p", f"compression:={args.compression}", "-p", f"log_time:={args.log_time}",
                "-p", f"overwrite:={str(args.overwrite).lower()}"]
    return recorder_main(ros_args)


if __name__ == "__main__":
    sys.exit(main())
