#!/usr/bin/env python3
"""``rabbit_policy.commands.evaluate`` as a script in a clone: Reproduce the paper's section IV for classic HZD, HZD-RL and the model-based recovery controller, with figures and a report.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.evaluate import main

if __name__ == "__main__":
    sys.exit(main())
