# Speed changes at every phase of a step (docs/learning.md, 2026-11-27 (later)).
#   .venv/bin/python docs/learning/speed_change_probe/two_segments.py learned classic recovery > two_segments.txt
# Each controller walks 6 s at the first command, then the second from 6 s + d (d = 0, 0.025, ..., 0.575 s:
# 24 points over a step), 14 s in all; a line per pair: how many of the 24 fell or stalled, and at which d.
import sys

import numpy as np

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy

PAIRS = [(1.4, 0.9), (1.5, 0.7), (1.5, 0.9), (1.4, 0.8), (1.3, 0.7), (1.2, 0.7), (0.7, 1.3), (0.7, 1.5), (0.8, 1.4),
         (0.9, 1.5)]
DELAYS = np.round(np.arange(0, 0.6, 0.025), 3)

for name in sys.argv[1:]:
    policy = make_policy(name)
    for a, b in PAIRS:
        fails = []
        for d in DELAYS:
            r = walk(policy, Scenario(schedule=((0.0, a), (6.0 + d, b))), 14.0)
            if r.fell or r.stalled:
                fails.append(float(d))
        print(name, a, b, len(fails), "of", len(DELAYS), fails, flush=True)
