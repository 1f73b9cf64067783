#!/usr/bin/env python3
"""``rabbit_sim.commands.plot_run`` as a script in a clone: Plot a recorded run (a rosbag2 bag from ``run_stack.py --record`` or ``record.py``).

``--help`` prints its options."""

import sys

from rabbit_sim.commands.plot_run import main

if __name__ == "__main__":
    sys.exit(main())
