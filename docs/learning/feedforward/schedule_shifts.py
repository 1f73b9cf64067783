# The tracking schedule (0.8 -> 1.2 -> 0.9 -> 1.5 -> 0.7 m/s, 10 s each; each change reached within 4 s) with every
# change moved by the same 0-200 ms (21 shifts): how often a policy passes it, not whether it passes the one
# schedule (docs/learning.md, 2026-11-27 (seventh)).
#   .venv/bin/python docs/learning/feedforward/schedule_shifts.py POLICY.pt ...
import json
import sys
from multiprocessing import get_context

from rabbit_policy.evaluation.acceptance import Criteria, schedule_check
from rabbit_policy.experiment.scenario import on_tick_grid
from rabbit_policy.runtime.policies import LearnedPolicy, make_policy

SHIFTS = tuple(0.01 * i for i in range(21))


def run(job):
    path, shift = job
    policy = make_policy("classic") if path == "classic" else LearnedPolicy(path)
    base = Criteria().schedule()
    schedule = (base[0],) + tuple((on_tick_grid(t + shift), v) for t, v in base[1:])
    check = schedule_check(policy, schedule)
    return [s["reach_time"] for s in check["segments"]], check["passed"]


with get_context("fork").Pool(2) as pool:
    for path in sys.argv[1:]:
        rows = pool.map(run, [(path, s) for s in SHIFTS])
        worst = [max((r[0][i] or 99.0) for r in rows) for i in range(len(rows[0][0]))]
        print(json.dumps({"policy": path, "passed_of": [sum(p for _, p in rows), len(rows)],
                          "worst_reach_per_segment": [round(w, 2) for w in worst]}), flush=True)
