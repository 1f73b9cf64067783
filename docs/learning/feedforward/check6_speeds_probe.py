# Check 6's return map (40 settle steps, 150 samples, one seed) at 14 speeds besides check 6's three.
#   .venv/bin/python docs/learning/feedforward/check6_speeds_probe.py POLICY.pt
import sys
from rabbit_policy.evaluation import stability as st
from rabbit_policy.runtime.policies import LearnedPolicy
path = sys.argv[1]
for speed in (0.75, 0.8, 0.85, 0.9, 0.95, 1.05, 1.1, 1.15, 1.2, 1.25, 1.35, 1.4, 1.45, 1.5):
    r = st.analyse_stability(LearnedPolicy(path), speed, True, samples=150)
    print(path.split('/')[-1], speed, "largest", round(float(r.analysis.magnitudes.max()), 3), flush=True)
