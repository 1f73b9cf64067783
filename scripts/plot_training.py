#!/usr/bin/env python3
"""``rabbit_policy.commands.plot_training`` as a script in a clone: Learning curves of one or more training runs (``train.py`` or ``train_sb3.py`` OUT directories) to one PNG: episode return, fall fraction, mean speed error and failed acceptance checks, against env steps (top row) and wall time (bottom row).

``--help`` prints its options."""

import sys

from rabbit_policy.commands.plot_training import main

if __name__ == "__main__":
    sys.exit(main())
