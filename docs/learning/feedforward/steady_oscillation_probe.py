# Step speeds 10-60 s into a walk at a constant command: their spread (the slow oscillation of the integral loop).
#   .venv/bin/python docs/learning/feedforward/steady_oscillation_probe.py POLICY.pt ...
import sys, numpy as np
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import LearnedPolicy
for path in sys.argv[1:]:
    p = LearnedPolicy(path)
    row = []
    for v in (0.8, 1.05, 1.3, 1.35, 1.45, 1.5):
        r = walk(p, Scenario(schedule=((0.0, v),)), 60.0)
        s = np.array([sp for a, _, sp in r.step_speeds() if a >= 10])
        row.append(f"{v}: std {s.std():.3f} range {s.min()-v:+.2f}..{s.max()-v:+.2f}")
    print(path.split('/')[-1], " | ".join(row), flush=True)
