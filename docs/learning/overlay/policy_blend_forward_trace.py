# Trace (docs/learning.md, 2026-11-27 (eighth)): +19 N s at 0.75 of a step at 0.7 m/s, the policy blend (falls) against the shipped
# blended overlay (walks). Needs /tmp/policy_blend_overlay.pt, which policy_blend.py writes.
#   .venv/bin/python docs/learning/overlay/policy_blend.py src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt none
#   .venv/bin/python docs/learning/overlay/policy_blend_forward_trace.py
import sys
from rabbit_policy.runtime.policies import LearnedPolicy
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.evaluation.robustness import phase_times
from rabbit_msgs_py.pushes import Push
for path in ("/tmp/policy_blend_overlay.pt", "src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt"):
    p = LearnedPolicy(path)
    t = phase_times(p, 0.7, 3.0, [0.75])[0]
    log = []
    orig = p.overlay.apply
    def apply(obs, cmd, orig=orig, p=p, log=log):
        out = orig(obs, cmd); log.append((round(obs.body[2], 2), round(obs.body[4], 2), round(p.overlay.last_weight, 2), round(obs.mean_speed, 2))); return out
    p.overlay.apply = apply
    r = walk(p, Scenario.constant(0.7, pushes=(Push(t, 190.0, 0.1),)), t + 5)
    print(path.split('/')[-1], "push at", round(t, 3), "failed", r.failed, "fell" if r.fell else "stalled" if r.failed else "", r.fall_time if r.fell else r.stall_time)
    print(" steps", [(round(s, 2), round(v, 3)) for s, e, v in r.step_speeds() if s > t - 1.0])
    k0 = int(t / 0.02)
    print(" w>0 after push", [(i * 0.02, x) for i, x in enumerate(log) if i >= k0 and x[2] > 0][:12])
