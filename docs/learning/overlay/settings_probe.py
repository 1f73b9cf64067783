# Probe (docs/learning.md, 2026-11-27 (eighth)): the shipped policy (the rule on top, blended) under other
# controller settings: check 4's backward margins and check 2's ordered changes.
#   .venv/bin/python docs/learning/overlay/settings_probe.py '{"within_step_until": 1.0}'
import json, sys
from dataclasses import replace
from rabbit_policy.evaluation.robustness import RobustnessConfig, push_margin, transitions
from rabbit_policy.runtime.policies import make_policy
settings = json.loads(sys.argv[1])
policy = make_policy("learned")
policy.controller_settings = settings
config = replace(RobustnessConfig(), max_impulse=30)
for v in config.push_speeds:
    m = push_margin(policy, v, -1, config)
    print(settings, "backward", v, m["largest_survived_Ns"], m["first_failing_phases"], flush=True)
t = transitions(policy, config)
print(settings, "ordered changes", t["passed"], "of", t["total"], "fell or stalled", t["fell_or_stalled"],
      [(p["from"], p["to"]) for p in t["pairs"] if p["fell_or_stalled"]], flush=True)
