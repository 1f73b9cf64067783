#!/usr/bin/env python3
"""``rabbit_policy.commands.ceiling_study`` as a script in a clone: The ceiling of each action family for backward-push recovery (rabbit_policy.evaluation.ceiling): an oracle that knows the push searches the actions after it with CMA-ES, on an impulse ladder of multiples of classic HZD's margin, at every speed and phase asked for. Results go to a JSON-lines file as they come (a rerun skips the cases already there), then a table per family and speed.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.ceiling_study import main

if __name__ == "__main__":
    sys.exit(main())
