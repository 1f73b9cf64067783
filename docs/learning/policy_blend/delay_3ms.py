# Probe (docs/learning.md, 2026-11-28): check 5's 3 ms torque delay at 0.7, 0.8 and 1.0 m/s (30 s walks; error: mean
# speed over the last 15 s - command) for the policy blend with the rule's weight free to rise at any phase
# (rise_until 1, as first shipped on 2026-11-28), the same with the offsets never added, with rise_until 0.6 (shipped),
# and the file shipped before (the overlay blended by the controller). Also how often the rule acted (w > 0).
#   git show 0f3b395:src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt > /tmp/prev_shipped.pt
#   .venv/bin/python docs/learning/policy_blend/delay_3ms.py > docs/learning/policy_blend/delay_3ms.txt
from dataclasses import replace

import numpy as np

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import LearnedPolicy

SHIPPED = "src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt"
for name in ("rise_until 1", "rise_until 1, no offsets", "rise_until 0.6", "shipped before"):
    for speed in (0.7, 0.8, 1.0):
        policy = LearnedPolicy("/tmp/prev_shipped.pt" if name == "shipped before" else SHIPPED)
        overlay = policy.overlay
        if name != "shipped before":
            overlay.config = replace(overlay.config, rise_until=1.0 if name.startswith("rise_until 1") else 0.6)
        if name.endswith("no offsets"):
            overlay.rule.with_offsets = lambda command, w: command
        weights = []
        apply = overlay.apply

        def logged(observation, command, apply=apply, overlay=overlay, weights=weights):
            out = apply(observation, command)
            weights.append(overlay.last_weight)
            return out

        overlay.apply = logged
        result = walk(policy, Scenario.constant(speed, torque_delay=0.003), 30.0)
        outcome = (("fell" if result.fell else "stalled") if result.failed
                   else f"walked, error {result.mean_speed(15.0) - speed:+.3f} m/s")
        w = np.array(weights)
        print(f"{name:26s} {speed} {outcome}; rule acted at {int((w > 0).sum())} decisions, w >= 0.5 at "
              f"{int((w >= 0.5).sum())}", flush=True)
