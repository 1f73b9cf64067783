#!/usr/bin/env python3
"""``scripts/walk.py``: ``rabbit_policy.commands.walk`` in a clone (installed, ``ros2 run rabbit_policy
walk``); ``--help`` prints its description and options."""

import sys

from rabbit_policy.commands.walk import main

if __name__ == "__main__":
    sys.exit(main())
