#!/usr/bin/env python3
"""``rabbit_policy.commands.probe_signal`` as a script in a clone: Measure the training signal of a preset before spending a seed on it.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.probe_signal import main

if __name__ == "__main__":
    sys.exit(main())
