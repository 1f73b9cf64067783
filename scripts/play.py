#!/usr/bin/env python3
"""``rabbit_sim.commands.play`` as a script in a clone: Replay a recorded bag on its topics, as ``ros2 bag play`` does (which is C++ and not on PyPI).

``--help`` prints its options."""

import sys

from rabbit_sim.commands.play import main

if __name__ == "__main__":
    sys.exit(main())
