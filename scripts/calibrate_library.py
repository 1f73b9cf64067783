#!/usr/bin/env python3
"""``rabbit_policy.commands.calibrate_library`` as a script in a clone: Calibrate the gait library's interpolation (``interpolation.json`` beside the gaits).

``--help`` prints its options."""

import sys

from rabbit_policy.commands.calibrate_library import main

if __name__ == "__main__":
    sys.exit(main())
