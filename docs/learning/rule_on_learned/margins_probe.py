# Probe: push margins (check 4's rule, its settle 3 s), a grid and the judged model cases of RuleOnLearned.
#   .venv/bin/python docs/learning/rule_on_learned/margins_probe.py RULE(0|1) SCALE FAST_GATE HANDOVER(0|1) HOLD(w, 0: off) BLENDED(0|1) [grid random back fwd models]
import sys, json
from dataclasses import replace
sys.path.insert(0, "docs/learning/rule_on_learned")
from rule_on_learned import RuleOnLearned
from rabbit_policy.evaluation.robustness import RobustnessConfig, push_margin, model_errors, speed_grid
from rabbit_policy.evaluation.acceptance import BroadCriteria
rule, scale, gate, handover = bool(int(sys.argv[1])), float(sys.argv[2]), float(sys.argv[3]), bool(int(sys.argv[4]))
hold = float(sys.argv[5])
blended = bool(int(sys.argv[6]))
what = sys.argv[7:] or ["grid", "back", "fwd", "models"]
p = RuleOnLearned(rule=rule, scale=scale, fast_gate=gate, handover=handover, hold=hold, blended=blended)
config = replace(RobustnessConfig(), max_impulse=30)
tag = f"rule={int(rule)} scale={scale} fast_gate={gate} handover={int(handover)} hold={hold} blended={int(blended)}"
if "grid" in what:
    g = speed_grid(p, config)
    print(tag, "grid", g.get("passed"), "of", len(g["rows"]), [(r["speed"], r["outcome"], None if r["error"] is None else round(r["error"], 3)) for r in g["rows"] if not r["passed"]], flush=True)
for d, name in ((-1, "back"), (1, "fwd")):
    if name in what:
        for v in config.push_speeds:
            m = push_margin(p, v, d, config)
            print(tag, name, v, m["largest_survived_Ns"], m["first_failing_phases"], flush=True)
if "random" in what:
    from rabbit_policy.evaluation.robustness import random_sequences
    rs = random_sequences(p, config)
    print(tag, "random", rs["passed"], "of", rs["total"], [(r["seed"], r["outcome"]) for r in rs["rows"] if r["outcome"] != "walked"], flush=True)
if "models" in what:
    rows = model_errors(p, config)["rows"]
    judged = BroadCriteria().judged_models
    print(tag, "judged", sum(r["passed"] for r in rows if r["case"] in judged), [(r["case"], r["speed"], r["outcome"], r["error"] and round(r["error"], 3)) for r in rows if not r["passed"]], flush=True)
