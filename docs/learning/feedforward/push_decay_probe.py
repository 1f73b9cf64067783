# Probe (docs/learning.md, 2026-11-27 (seventh)): the windup decay also after a disturbance at a constant command,
# patched into SpeedIntegral.update. B = 0: off. Output: push_decay_probe.txt (the policy with the start feed-forward).
#   .venv/bin/python docs/learning/feedforward/push_decay_probe.py POLICY.pt 0.1
"""Probe: the windup decay also after a disturbance at a constant command: when |e| first reaches B
(from below) at least `seconds` after the last change (or the start), treat it as a change."""
import sys, json
import numpy as np
sys.path.insert(0, "docs/learning/settling")
from settling import draws, TOLERANCE
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import LearnedPolicy
from rabbit_policy.runtime import speed_integral as si
from rabbit_msgs_py.pushes import Push
from rabbit_policy.evaluation.robustness import RobustnessConfig, model_errors
from rabbit_policy.evaluation.acceptance import BroadCriteria
B = float(sys.argv[2]); policy_file = sys.argv[1]
orig = si.SpeedIntegral.update
def upd(self, e, v):
    prev_e = getattr(self, "_prev_e", 0.0); self._prev_e = e
    if B > 0 and self._last_command is not None and v == self._last_command and self._looking == 0 \
            and abs(e) >= B and abs(prev_e) < B:
        if not (self._decaying and self._since <= self._window):
            self._anchor = self.value
        self._looking, self._direction, self._decaying, self._since = self._window, float(np.sign(e)), False, 0
    return orig(self, e, v)
si.SpeedIntegral.update = upd
p = LearnedPolicy(policy_file)
for shift in (0.0, 0.02, -0.02, 0.1):
    r = walk(p, Scenario(schedule=((0.0, 0.8), (6.0 + shift, 1.4), (13.0, 0.9), (18.0, 1.2)), pushes=(Push(20.0, -60.0, 0.1),)), 26.0)
    print(B, "demo shift", shift, [round(s["mean_speed"], 3) for s in r.summary()["segments"]], flush=True)
# pushes at constant speed: late error
errs = []
for v in (0.8, 1.0, 1.2, 1.4):
    for t in (8.0, 8.15, 8.3, 8.45):
        for f in (-60.0, 60.0, -100.0):
            r = walk(p, Scenario(schedule=((0.0, v),), pushes=(Push(t, f, 0.1),)), 16.0)
            errs.append(None if r.failed else round(r.mean_speed(11, 16) - v, 3))
ok = [e for e in errs if e is not None]
print(B, "push late err: failed", errs.count(None), "within", sum(abs(e) <= 0.03 for e in ok), "of", len(errs), "mean|e|", round(float(np.mean(np.abs(ok))), 4), flush=True)
models = model_errors(p, RobustnessConfig())["rows"]
judged = BroadCriteria().judged_models
print(B, "judged", sum(m["passed"] for m in models if m["case"] in judged), [(m["case"], m["speed"], m["outcome"]) for m in models if not m["passed"]], flush=True)
