#!/usr/bin/env python3
"""``rabbit_policy.commands.compare_policies`` as a script in a clone: Checks 1-6 (the learning issue's broad acceptance) on several learned policies against one classic reference, measured once: the ablation's table.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.compare_policies import main

if __name__ == "__main__":
    sys.exit(main())
