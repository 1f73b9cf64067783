#!/usr/bin/env python3
"""``rabbit_policy.commands.tune_recovery`` as a script in a clone: Tune the recovery controller's constants on a push grid (rabbit_policy.gait_design.recovery_tuning): CMA-ES over its four offsets and saturation, from the packaged constants; prints JSON (the best constants, pushes survived, each generation's scores).

``--help`` prints its options."""

import sys

from rabbit_policy.commands.tune_recovery import main

if __name__ == "__main__":
    sys.exit(main())
