#!/usr/bin/env python3
"""``rabbit_policy.commands.optimize_gaits`` as a script in a clone: Regenerate the classic HZD gait library (the paper's FROST baseline, in Python).

``--help`` prints its options."""

import sys

from rabbit_policy.commands.optimize_gaits import main

if __name__ == "__main__":
    sys.exit(main())
