#!/usr/bin/env python3
"""``rabbit_policy.commands.demo`` as a script in a clone: make demo: the learned controller on the ROS 2 stack, judged beside classic.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.demo import main

if __name__ == "__main__":
    sys.exit(main())
