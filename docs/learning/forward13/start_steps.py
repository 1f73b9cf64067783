# Step speeds (start s: mean m/s) of the first 22 steps of a walk at 1.3 m/s, per controller.
#   .venv/bin/python docs/learning/forward13/start_steps.py > docs/learning/forward13/start_steps_1.3.txt
import sys
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import make_policy
for kind in ("learned", "classic", "integral"):
    p = make_policy("classic", speed_integral=0.2) if kind == "integral" else make_policy(kind)
    r = walk(p, Scenario.constant(1.3), 12.0)
    print(kind, " ".join(f"{s:.2f}:{v:.3f}" for s, e, v in r.step_speeds()[:22]), flush=True)
