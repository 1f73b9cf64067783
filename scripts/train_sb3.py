#!/usr/bin/env python3
"""``rabbit_policy.commands.train_sb3`` as a script in a clone: The stable-baselines3 baseline: SB3's PPO (or SAC) on ``RabbitHZD-v0``, the actor our network's shape, judged by the same acceptance as ``train.py`` and written the same way (``rabbit_policy.learning.sb3``).

``--help`` prints its options."""

import sys

from rabbit_policy.commands.train_sb3 import main

if __name__ == "__main__":
    sys.exit(main())
