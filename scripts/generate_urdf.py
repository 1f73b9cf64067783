#!/usr/bin/env python3
"""``rabbit_sim.commands.generate_urdf`` as a script in a clone: Write the URDF of RABBIT generated from the MuJoCo model (``rabbit_sim.urdf``).

``--help`` prints its options."""

import sys

from rabbit_sim.commands.generate_urdf import main

if __name__ == "__main__":
    sys.exit(main())
