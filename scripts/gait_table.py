#!/usr/bin/env python3
"""``rabbit_policy.commands.gait_table`` as a script in a clone: Print the classic gait library as a Markdown table (for the README and reports).

``--help`` prints its options."""

import sys

from rabbit_policy.commands.gait_table import main

if __name__ == "__main__":
    sys.exit(main())
