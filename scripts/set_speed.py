#!/usr/bin/env python3
"""``scripts/set_speed.py``: ``rabbit_policy.commands.set_speed`` in a clone (installed, ``ros2 run rabbit_policy
set_speed``); ``--help`` prints its description and options."""

import sys

from rabbit_policy.commands.set_speed import main

if __name__ == "__main__":
    sys.exit(main())
