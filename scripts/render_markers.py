#!/usr/bin/env python3
"""``rabbit_sim.commands.render_markers`` as a script in a clone: Draw the ``/rabbit/markers`` of a recorded bag side-on (what RViz/Foxglove show) to a PNG, without a GUI.

``--help`` prints its options."""

import sys

from rabbit_sim.commands.render_markers import main

if __name__ == "__main__":
    sys.exit(main())
