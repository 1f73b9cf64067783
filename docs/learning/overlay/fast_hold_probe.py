# Probe (docs/learning.md, 2026-11-27 (eighth)): the policy blend with its fast gate held for HOLD s after the
# hip's mean speed last exceeded the command by 10 % (a forward push's aftermath), so the rule's reference,
# still the post-push fast steps, cannot raise a false alarm. Check 4's margins at 0.7/1.0/1.3 m/s.
#   .venv/bin/python docs/learning/overlay/policy_blend.py src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt none
#   .venv/bin/python docs/learning/overlay/fast_hold_probe.py HOLD_S [back fwd]
# Measured on the first policy blend (before AlphaBlend, commit 0f3b395); on today's package it runs the new blend.
import sys
from dataclasses import replace
from rabbit_policy.evaluation.robustness import RobustnessConfig, push_margin
from rabbit_policy.parallel import LocalBackend
from rabbit_policy.runtime.policies import LearnedPolicy
from rabbit_policy.runtime.recovery import RecoveryOverlay

HOLD = float(sys.argv[1])


class FastHoldOverlay(RecoveryOverlay):
    def reset(self) -> None:
        super().reset()
        self._quiet_for = 10 ** 9

    def apply(self, observation, command):
        fast = observation.mean_speed > observation.desired_speed * (1.0 + self.config.fast_gate)
        self._quiet_for = 0 if fast else getattr(self, "_quiet_for", 10 ** 9) + 1
        out = super().apply(observation, command)
        if self._quiet_for * self.rule.decision_period * 0.001 < HOLD and self.last_weight > 0.0:  # held off: the policy's gait
            self.last_weight = 0.0
            self._held = command if not self.config.policy_blend else self.blended_now
            return self._held
        return out

    def blended(self, observation, command):
        self.blended_now = super().blended(observation, command)
        return self.blended_now


policy = LearnedPolicy("/tmp/policy_blend_overlay.pt")
policy.overlay.__class__ = FastHoldOverlay
policy.overlay.reset()
what = sys.argv[2:] or ["back", "fwd"]
config = replace(RobustnessConfig(), max_impulse=30)
backend = LocalBackend(2)
for d, name in ((-1, "back"), (1, "fwd")):
    if name in what:
        for v in config.push_speeds:
            m = push_margin(policy, v, d, config, backend.map)
            print("fast hold", HOLD, name, v, m["largest_survived_Ns"], m["first_failing_phases"], flush=True)
backend.close()
