# How much of make demo's outcome is rounding? (docs/learning.md, 2026-11-27 (later))
#   .venv/bin/python docs/learning/speed_change_probe/rounding.py 0 60 > rounding.txt
# The shipped learned policy walks make demo's kind of schedule (0.8, 1.4 from 6 s, 0.9 from 12 s, 1.2 from 18 s; make demo's own changes at 13 s;
# 24 s) on the fast path with every action multiplied by (1 + u), u uniform in +-1e-7 (float32 rounding's
# size), one seed per line: (seed, fell, stalled, stall time, touchdowns).
import sys

import numpy as np

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy

SCENARIO = Scenario(schedule=((0.0, 0.8), (6.0, 1.4), (12.0, 0.9), (18.0, 1.2)))


class Rounded:
    """The policy's forward pass with a relative error of at most 1e-7 on every output."""

    def __init__(self, forward, rng: np.random.Generator) -> None:
        self.forward, self.rng = forward, rng
        self.offset, self.low, self.high = forward.offset, forward.low, forward.high

    def __call__(self, x):
        y = self.forward(x)
        return y * (1 + self.rng.uniform(-1e-7, 1e-7, y.shape))


for seed in range(int(sys.argv[1]), int(sys.argv[2])):
    policy = make_policy("learned")
    policy.forward = Rounded(policy.forward, np.random.default_rng(seed))
    r = walk(policy, SCENARIO, 24.0)
    print((seed, r.fell, r.stalled, r.stall_time, len(r.touchdowns)), flush=True)
