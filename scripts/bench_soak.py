#!/usr/bin/env python3
"""``rabbit_policy.commands.bench_soak`` as a script in a clone: Soak benchmark: the ROS 2 stack for an hour of sim time; prints one JSON object.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.bench_soak import main

if __name__ == "__main__":
    sys.exit(main())
