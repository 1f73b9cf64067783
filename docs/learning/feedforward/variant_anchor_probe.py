# (docs/learning.md, 2026-11-27 (seventh); variants.txt)
#   .venv/bin/python docs/learning/feedforward/variant_anchor_probe.py POLICY.pt 60 37
"""Probe: the feed-forward moves the windup decay's anchor (I decays toward I at the change + I*(new) - I*(old)
once the hip has passed the new command) instead of I itself at the change."""
import sys, json
sys.path.insert(0, "docs/learning/settling")
import settling
from rabbit_policy.runtime.policies import LearnedPolicy
from rabbit_policy.runtime import speed_integral as si
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_msgs_py.pushes import Push
orig = si.SpeedIntegral.update
def upd(self, error, desired_speed):
    previous = self._last_command
    ff = self.config.feedforward
    object.__setattr__(self.config, "feedforward", None)
    try:
        value = orig(self, error, desired_speed)
    finally:
        object.__setattr__(self.config, "feedforward", ff)
    if ff is not None and previous is not None and desired_speed != previous:
        self._anchor += ff.at(desired_speed) - ff.at(previous)
    return value
si.SpeedIntegral.update = upd
p = LearnedPolicy(sys.argv[1])
for shift in (0.0, 0.02, -0.02, 0.04, 0.3):
    r = walk(p, Scenario(schedule=((0.0, 0.8), (6.0 + shift, 1.4), (13.0, 0.9), (18.0, 1.2)), pushes=(Push(20.0, -60.0, 0.1),)), 26.0)
    print("demo shift", shift, [round(s["mean_speed"], 3) for s in r.summary()["segments"]], flush=True)
settling.make_policy = lambda name: p
r = settling.measure("learned", int(sys.argv[2]), int(sys.argv[3]))
rows = r["rows"]
print(json.dumps({k: v for k, v in r.items() if not isinstance(v, list)}))
for lo, hi, name in ((0.4, 9, "up>=0.4"), (0.1, 0.4, "up<0.4"), (-9, -0.4, "down>=0.4"), (-0.4, -0.1, "down<0.4")):
    sel = [x for x in rows if lo <= x["to"] - x["from"] < hi and x["error_3_10"] is not None]
    print(name, len(sel), "3-10 within", sum(abs(x["error_3_10"]) <= 0.03 for x in sel), "5-10 within", sum(abs(x["error_5_10"]) <= 0.03 for x in sel))
