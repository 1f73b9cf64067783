# A walk at 0.8 m/s with the shipped policy, per step: mean speed, mean I, mean Kd output, share of saturated outputs,
# step time (docs/learning.md, 2026-11-27 (seventh)).   .venv/bin/python docs/learning/feedforward/oscillation_08_probe.py
import numpy as np
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import LearnedPolicy
p = LearnedPolicy("src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt")
rec = []
orig_forward = p.forward
class F:
    def __init__(s, f): s.f = f; s.low = f.low; s.high = f.high
    def __call__(s, x):
        a = s.f(x); rec.append((x[0], x[1], x[3], a.copy())); return a
p.forward = F(orig_forward)
r = walk(p, Scenario(schedule=((0.0, 0.8),)), 40.0)
acts = np.array([a for *_, a in rec]); low, high = p.forward.low.astype(float), p.forward.high.astype(float)
norm = 2 * (acts - low) / (high - low) - 1
print("decisions", len(rec), "frac at |norm|>0.95 per output:", np.round((np.abs(norm) > 0.95).mean(axis=0), 2))
steps = r.step_speeds()
dt = 0.02
for (t0, t1, sp) in steps:
    i0, i1 = int(t0 / dt), max(int(t0 / dt) + 1, int(t1 / dt))
    seg = rec[i0:i1]
    I = np.mean([s[2] for s in seg]); kd = np.mean([s[3][-1] for s in seg])
    sat = np.mean(np.abs(norm[i0:i1]) > 0.95)
    print(f"{t0:5.1f}-{t1:5.1f} v {sp:.3f} I {I:+.3f} Kd {kd:6.2f} sat {sat:.2f} T {t1-t0:.3f}")
