#!/usr/bin/env python3
"""``rabbit_policy.commands.screen_policies`` as a script in a clone: Choose among a training run's policies on held-out checks (``rabbit_policy.evaluation.selection``): the ordered speed changes at other phases, random command sequences from other seeds and the judged model errors at other speeds than checks 1-6 use, so that the policy chosen can then be judged on checks 1-6 (``scripts/compare_policies.py``) without having been chosen on them.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.screen_policies import main

if __name__ == "__main__":
    sys.exit(main())
