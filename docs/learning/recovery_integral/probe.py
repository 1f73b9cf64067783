# The recovery controller with Westervelt's speed integral under it (docs/learning.md, 2026-11-27 (fourth)): does
# speed feedback buy the model cases without losing the pushes and the settling?
#   .venv/bin/python docs/learning/recovery_integral/probe.py GAIN models,back,settle,random,trans >> docs/learning/recovery_integral/probe.jsonl
# The classic base (LibraryPolicy with the integral, updated each time the base decides) under the recovery rule, as
# make_policy builds "recovery" but with the gain. The rule holds the base gait from 0.2 of phase to the touchdown,
# so the integral is updated only in the first ~0.2 of each step (about a fifth of the rate classic + integral has):
# the gain is not comparable with classic's. Parts: the judged model cases of checks 1-6 (5), the backward margins
# (4), settling.py's 60 changes, the 100 random sequences (3) and the ordered changes (2), as checks 1-6 run them.
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "settling"))
from rabbit_policy.evaluation import robustness as rb
from rabbit_policy.runtime.policies import LibraryPolicy
from rabbit_policy.runtime.recovery import RecoveryPolicy
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.speed_integral import decision_dt
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
import settling  # noqa: E402

gain = float(sys.argv[1])
parts = sys.argv[2].split(",")
lib = GaitLibrary.load()


def build():
    return RecoveryPolicy(LibraryPolicy(lib, "interpolate", gain, decision_dt(20)), decision_period=20)

p = build()
cfg = rb.RobustnessConfig()
out = {"gain": gain}
t0 = time.time()
if "models" in parts:
    m = rb.model_errors(p, cfg)
    judged = ("drives", "friction 0.5", "friction 0.4", "torso mass -15 %", "torso mass +15 %", "torque delay 3 ms")
    rows = [r for r in m["rows"] if r["case"] in judged]
    out["models_judged_ok"] = sum(r["outcome"] == "walked" and r["error"] is not None and abs(r["error"]) <= 0.05 for r in rows)
    out["models"] = [(r["case"], r["speed"], r["outcome"], None if r["error"] is None else round(r["error"], 3)) for r in m["rows"]]
if "trans" in parts:
    tr = rb.transitions(p, cfg)
    out["transitions"] = [tr["passed"], tr["total"], tr["fell_or_stalled"]]
    out["transitions_fell"] = [(x["from"], x["to"], x["phase"], x["outcome"]) for x in tr["rows"] if x["outcome"] != "walked"]
if "random" in parts:
    rs = rb.random_sequences(p, cfg)
    out["random"] = rs["passed"]
    out["random_failed"] = [(x["seed"], x["outcome"]) for x in rs["rows"] if x["outcome"] != "walked"]
if "back" in parts:
    out["back"] = [rb.push_margin(p, v, -1, cfg)["largest_survived_Ns"] for v in (0.7, 1.0, 1.3)]
if "fwd" in parts:
    out["fwd"] = [rb.push_margin(p, v, 1, cfg)["largest_survived_Ns"] for v in (0.7, 1.0, 1.3)]
if "settle" in parts:
    rows = []
    for a, b, t in settling.draws(settling.CHANGES):
        r = walk(p, Scenario(schedule=((0.0, a), (t, b))), t + 10.0)
        rows.append(None if r.failed else r.mean_speed(t + 5.0, t + 10.0) - b)
    out["settled"] = sum(e is not None and abs(e) <= 0.03 for e in rows)
    out["settle_failed"] = sum(e is None for e in rows)
out["wall"] = round(time.time() - t0)
print(json.dumps(out), flush=True)
