#!/usr/bin/env python3
"""``rabbit_policy.commands.train`` as a script in a clone: Train the HZD-RL policy on ``RabbitHZD-v0`` with Evolution Strategies or PPO.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.train import main

if __name__ == "__main__":
    sys.exit(main())
