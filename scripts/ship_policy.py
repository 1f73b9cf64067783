#!/usr/bin/env python3
"""``rabbit_policy.commands.ship_policy`` as a script in a clone: Ship a trained HZD-RL policy as ``rabbit_policy``'s package data, with a model card.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.ship_policy import main

if __name__ == "__main__":
    sys.exit(main())
