#!/usr/bin/env python3
"""``rabbit_policy.commands.bench_train`` as a script in a clone: Benchmark HZD-RL training: environment throughput and wall time to a passing policy.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.bench_train import main

if __name__ == "__main__":
    sys.exit(main())
