#!/usr/bin/env python3
"""``rabbit_policy.commands.robustness`` as a script in a clone: The broad evaluation of one or both controllers (``rabbit_policy.evaluation.robustness``): every speed, every speed change at several phases, random command sequences, push margins at every phase, model errors. ROS-free; prints one JSON object (``--out`` also writes it).

``--help`` prints its options."""

import sys

from rabbit_policy.commands.robustness import main

if __name__ == "__main__":
    sys.exit(main())
