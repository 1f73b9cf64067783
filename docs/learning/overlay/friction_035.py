# Probe (docs/learning.md, 2026-11-27 (eighth)): the "no fall at friction 0.35": 30 s walks at
# 0.7-1.5 m/s every 0.1 on friction 0.35, per controller; the mean speed error over the last 15 s.
#   .venv/bin/python docs/learning/overlay/friction_035.py classic|recovery|learned [POLICY.pt]
import sys
import numpy as np
from rabbit_sim.model import ModelOptions
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy
kind = sys.argv[1]
policy = make_policy(kind, policy_file=sys.argv[2]) if len(sys.argv) > 2 else make_policy(kind)
rows = []
for v in np.round(np.arange(0.7, 1.501, 0.1), 2):
    r = walk(policy, Scenario.constant(float(v), model=ModelOptions(friction=0.35)), 30.0)
    rows.append((float(v), "fell" if r.fell else "stalled" if r.failed else round(r.mean_speed(15.0) - v, 3)))
print(kind, sys.argv[2:] , "failed", sum(isinstance(o, str) for _, o in rows), "of", len(rows), rows, flush=True)
