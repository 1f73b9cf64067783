# Probe (docs/learning.md, 2026-11-27 (eighth)): does the forward push margin at 1.3 m/s depend on
# when in the walk the push lands? Check 4 pushes in the first step after 3 s; here the first step
# after each of several settle times, at check 4's eight phases, the impulse raised until one fails.
#   .venv/bin/python docs/learning/forward13/settle_probe.py KIND SPEED DIRECTION [SETTLE ...]
# KIND: classic | recovery | integral (classic + speed integral 0.2) | learned (the shipped policy)
import sys
from dataclasses import replace
from rabbit_policy.evaluation.robustness import RobustnessConfig, push_margin
from rabbit_policy.runtime.policies import make_policy

kind, speed, direction = sys.argv[1], float(sys.argv[2]), int(sys.argv[3])
settles = [float(s) for s in sys.argv[4:]] or [3.0, 4.0, 6.0, 10.0, 20.0]
policy = (make_policy("classic", speed_integral=0.2) if kind == "integral" else make_policy(kind))
for settle in settles:
    config = replace(RobustnessConfig(), push_settle=settle, max_impulse=30)
    m = push_margin(policy, speed, direction, config)
    print(kind, speed, direction, "settle", settle, "margin", m["largest_survived_Ns"],
          "first failing phases", m["first_failing_phases"], flush=True)
