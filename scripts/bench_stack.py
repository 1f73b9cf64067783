#!/usr/bin/env python3
"""``rabbit_policy.commands.bench_stack`` as a script in a clone: Benchmark the ROS 2 stack; prints one JSON object.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.bench_stack import main

if __name__ == "__main__":
    sys.exit(main())
