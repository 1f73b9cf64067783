# Start transients (mean speed 3-6 s and 5-10 s into a walk at each of 33 speeds) and make demo's schedule with
# its first change moved by a few ms.
#   .venv/bin/python docs/learning/feedforward/start_and_demo_probe.py POLICY.pt
import sys, json, numpy as np
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import LearnedPolicy
from rabbit_msgs_py.pushes import Push
p = LearnedPolicy(sys.argv[1])
starts = {}
for v in np.arange(0.7, 1.501, 0.025):
    r = walk(p, Scenario(schedule=((0.0, float(v)),)), 10.0)
    starts[round(float(v), 3)] = (r.failed, round(r.mean_speed(3, 6) - v, 3), round(r.mean_speed(5, 10) - v, 3))
print("starts 3-6 within", sum(abs(s[1]) <= 0.03 for s in starts.values()), "5-10 within", sum(abs(s[2]) <= 0.03 for s in starts.values()), "of", len(starts), json.dumps(starts), flush=True)
for shift in (0.0, 0.001, 0.02, -0.02, 0.04, 0.1, 0.3):
    r = walk(p, Scenario(schedule=((0.0, 0.8), (6.0 + shift, 1.4), (13.0, 0.9), (18.0, 1.2)), pushes=(Push(20.0, -60.0, 0.1),)), 26.0)
    print("demo shift", shift, [round(s["mean_speed"], 3) for s in r.summary()["segments"]], flush=True)
