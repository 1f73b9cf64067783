"""Confirmation probe (issue 72): the start and seed 3's generation-30 network of the
screen-guarded run on the screen's pushes at phases (k + 0.5)/32 (none of the screen's, none the
selection's speeds), the screen's changes at phases shifted by 0.05 (paired, McNemar)."""
import json, sys
from dataclasses import replace
from math import comb
from rabbit_policy.evaluation.shipping import ScreenTrials, screen_outcomes
from rabbit_policy.parallel import LocalBackend
from rabbit_policy.spec import load_controller
R = "/work/runs/screen_guarded/"
trials = replace(ScreenTrials(), phase_offset=0.5, change_phases=tuple(round((k + 0.35) / 10, 3) for k in range(10)))
backend = LocalBackend(2)
out = {}
for name, path in (("start", R + "seed-3/start.yaml"), ("seed-3", R + "seed-3/run/evaluated/00030.yaml"),
                   ("seed-2", R + "seed-2/run/evaluated/00030.yaml")):
    out[name] = screen_outcomes(load_controller(path), trials, backend.map)
    print(name, {f: f"{sum(o)}/{len(o)}" for f, o in out[name].items()}, sum(sum(o) for o in out[name].values()), flush=True)
def mc(b, c):
    n = b + c
    return 1.0 if n == 0 else min(1.0, 2 * sum(comb(n, i) for i in range(min(b, c) + 1)) / 2 ** n)
for cand in ("seed-3", "seed-2"):
    a = [x for f in out[cand] for x in out[cand][f]]; s = [x for f in out["start"] for x in out["start"][f]]
    b_ = sum(1 for x, y in zip(a, s) if x and not y); c_ = sum(1 for x, y in zip(a, s) if y and not x)
    print(cand, "vs start", b_, "-", c_, "p =", mc(b_, c_), flush=True)
json.dump(out, open("/work/runs/confirm.json", "w"))
