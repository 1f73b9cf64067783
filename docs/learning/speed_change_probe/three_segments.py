# make demo's kind of schedule at every phase of the deceleration (docs/learning.md, 2026-11-27 (later)).
#   .venv/bin/python docs/learning/speed_change_probe/three_segments.py learned classic recovery > three_segments.txt
# first command, then hi from 6 s, then lo from 12 s + d (d = 0, 0.025, ..., 0.575 s), 20 s in all; a line
# per schedule: how many of the 24 fell or stalled, with (d, the time it stopped).
import sys

import numpy as np

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy

DELAYS = np.round(np.arange(0, 0.6, 0.025), 3)

for name in sys.argv[1:]:
    policy = make_policy(name)
    for first in (0.8, 0.7, 1.0):
        for hi, lo in ((1.4, 0.9), (1.5, 0.8), (1.3, 0.9)):
            fails = []
            for d in DELAYS:
                r = walk(policy, Scenario(schedule=((0.0, first), (6.0, hi), (12.0 + d, lo))), 20.0)
                if r.fell or r.stalled:
                    fails.append((float(d), r.stall_time or r.fall_time))
            print(name, first, hi, lo, len(fails), "of", len(DELAYS), fails, flush=True)
