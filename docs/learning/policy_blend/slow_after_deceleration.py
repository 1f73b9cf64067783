# Probe (docs/learning.md, 2026-11-28): four of seed 38's settling changes that the first policy blend (rise_until 1,
# shipped first on 2026-11-28: first/; the .txt was measured on it) ends slow, 5-10 s after a deceleration, run by:
# the shipped file; the same with the rule's offsets never added (its weight and hold still computed); the file
# shipped before (the overlay blended by the controller, HEAD~ of the ship commit, written to /tmp/prev_shipped.pt by
# `git show`). Error: mean speed 5-10 s after the change - command.
#   git show 0f3b395:src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt > /tmp/prev_shipped.pt
#   .venv/bin/python docs/learning/policy_blend/slow_after_deceleration.py > docs/learning/policy_blend/slow_after_deceleration.txt
import sys
import numpy as np
sys.path.insert(0, "docs/learning/settling")
import settling
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import LearnedPolicy
rows = settling.draws(200, 38)
picks = [r for r in rows if (r[0], r[1]) in ((1.211, 0.864), (0.927, 0.805), (1.097, 0.796), (1.485, 1.016))]
P = "src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt"
for a, b, t in picks:
    out = []
    for name in ("shipped", "no offsets", "prev"):
        p = LearnedPolicy("/tmp/prev_shipped.pt" if name == "prev" else P)
        if name == "no offsets":
            p.overlay.rule.with_offsets = lambda command, w: command
        r = walk(p, Scenario(schedule=((0.0, a), (t, b))), t + 10.0)
        out.append(f"{name} {r.mean_speed(t + 5, t + 10) - b:+.3f}" + (" FAILED" if r.failed else ""))
    print(a, b, t, " | ".join(out), flush=True)
