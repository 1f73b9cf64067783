#!/usr/bin/env python3
"""``scripts/run_stack.py``: ``rabbit_policy.commands.run_stack`` in a clone (installed, ``ros2 run rabbit_policy
run_stack``); ``--help`` prints its description and options."""

import sys

from rabbit_policy.commands.run_stack import main

if __name__ == "__main__":
    sys.exit(main())
