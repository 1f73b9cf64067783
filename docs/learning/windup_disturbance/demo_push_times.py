"""Probe: the demo's scenario with its push moved across 19.0-21.0 s; each spec's segment means (m/s)."""
import sys
import numpy as np
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario, parse_schedule, Push
from rabbit_policy.spec import load_controller
from rabbit_policy.spec.make import make_policy

for spec in sys.argv[1:]:
    off = []
    for t in np.round(np.arange(19.0, 21.01, 0.2), 2):
        pol = make_policy("classic") if spec == "classic" else load_controller(spec)
        r = walk(pol, Scenario(parse_schedule("0:0.8,6:1.4,13:0.9,18:1.2"), pushes=(Push(float(t), -60.0, 0.1),)), 26.0)
        means = [s["mean_speed"] for s in r.segments()]
        errs = [abs(m - s["command"]) if m is not None else 9 for m, s in zip(means, r.segments())]
        off.append(max(errs))
        print(spec.split("/")[-1], t, [round(m, 3) if m else None for m in means], "fell" if r.fell else "", flush=True)
    print(spec.split("/")[-1], "worst error per push time:", [round(e, 3) for e in off],
          "within 0.03:", sum(e <= 0.03 for e in off), "within 0.05:", sum(e <= 0.05 for e in off), "of", len(off))
