#!/usr/bin/env python3
"""``rabbit_policy.commands.bench_sim`` as a script in a clone: Benchmark: closed-loop steps per second against raw ``mj_step`` steps per second on the same model, in the same process.

``--help`` prints its options."""

import sys

from rabbit_policy.commands.bench_sim import main

if __name__ == "__main__":
    sys.exit(main())
