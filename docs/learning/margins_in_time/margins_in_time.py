# Study (docs/learning.md, 2026-11-27 (eighth)): check 4's push margin (the largest impulse survived at
# all eight phases of one step), measured at the first step after several times into the walk instead of
# after 3 s only. One JSON line per (controller, speed, direction, settle).
#   .venv/bin/python docs/learning/margins_in_time/margins_in_time.py KIND [SETTLE ...] >> margins.jsonl
# KIND: classic | recovery | learned (the shipped policy) | integral (classic + speed integral 0.2)
#       | rule-on-learned (docs/learning/rule_on_learned/rule_on_learned.py)
import sys, json
from dataclasses import replace
from rabbit_policy.evaluation.robustness import RobustnessConfig, push_margin
from rabbit_policy.runtime.policies import make_policy

kind = sys.argv[1]
settles = [float(s) for s in sys.argv[2:]] or [3.0, 6.0, 10.0, 15.0]
if kind == "integral":
    policy = make_policy("classic", speed_integral=0.2)
elif kind == "rule-on-learned":
    sys.path.insert(0, "docs/learning/rule_on_learned")
    from rule_on_learned import RuleOnLearned
    policy = RuleOnLearned()
else:
    policy = make_policy(kind)
for speed in (0.7, 1.0, 1.3):
    for direction in (-1, 1):
        for settle in settles:
            config = replace(RobustnessConfig(), push_settle=settle, max_impulse=40)
            m = push_margin(policy, speed, direction, config)
            print(json.dumps({"controller": kind, "speed": speed, "direction": "forward" if direction > 0 else "backward",
                              "settle_s": settle, "margin_Ns": m["largest_survived_Ns"],
                              "first_failing_phases": m["first_failing_phases"]}), flush=True)
