# Probe (docs/learning.md, 2026-11-28): the policy blend with the rule's weight frozen late in the step: from
# phase LATE until the touchdown, w may fall but not rise above its value at LATE. With the controller applying
# gaits at once, offsets that rise late move the swing leg's path just before it lands (the forward failure at
# 0.7 m/s traced in policy_blend_forward_trace.txt: w 0.9-1.0 at 0.77-0.8 of the step). Blended by the controller
# (the shipped overlay), a gait after 0.6 of phase waits for the touchdown for the same reason.
#   .venv/bin/python docs/learning/overlay/policy_blend.py src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt none
#   .venv/bin/python docs/learning/overlay/late_freeze_probe.py LATE [FAST_HOLD_S] [back fwd]
# Measured (late_freeze_06.txt) on the first policy blend (before AlphaBlend, commit 0f3b395); on today's package
# it runs AlphaBlend, which with LATE 0.6 is the shipped OverlayConfig(rise_until=0.6).
import sys
from dataclasses import replace
from rabbit_policy.evaluation.robustness import RobustnessConfig, push_margin
from rabbit_policy.parallel import LocalBackend
from rabbit_policy.runtime.policies import LearnedPolicy
from rabbit_policy.runtime.recovery import RecoveryOverlay

LATE = float(sys.argv[1])
FAST_HOLD = float(sys.argv[2]) if len(sys.argv) > 2 and sys.argv[2][0].isdigit() else 0.0


class LateFreezeOverlay(RecoveryOverlay):
    def reset(self) -> None:
        super().reset()
        self._cap = None
        self._quiet_for = 10 ** 9

    def apply(self, observation, command):
        if self.config.policy_blend:
            command = self.blended(observation, command)
        tau = observation.body[2]
        self.rule.act(observation)
        w = self.rule.last_weight
        fast = self.config.fast_gate > 0.0 and observation.mean_speed > observation.desired_speed * (1.0 + self.config.fast_gate)
        self._quiet_for = 0 if fast else getattr(self, "_quiet_for", 10 ** 9) + 1
        if fast or self._quiet_for * self.rule.decision_period * 0.001 < FAST_HOLD:
            w = 0.0
        if tau >= LATE:
            if getattr(self, "_cap", None) is None:
                self._cap = self.last_weight  # w at the last decision before LATE
            w = min(w, self._cap)
        else:
            self._cap = None
        self.last_weight = w
        if w <= 0.0:
            self._held = command
            return command
        if w >= self.config.hold and self._held is not None:
            command = self._held
        return self.rule.with_offsets(command, w)


policy = LearnedPolicy("/tmp/policy_blend_overlay.pt")
policy.overlay.__class__ = LateFreezeOverlay
policy.overlay.reset()
what = [a for a in sys.argv[2:] if a in ("back", "fwd")] or ["back", "fwd"]
config = replace(RobustnessConfig(), max_impulse=30)
backend = LocalBackend(2)
for d, name in ((-1, "back"), (1, "fwd")):
    if name in what:
        for v in config.push_speeds:
            m = push_margin(policy, v, d, config, backend.map)
            print("late freeze", LATE, "fast hold", FAST_HOLD, name, v, m["largest_survived_Ns"], m["first_failing_phases"], flush=True)
backend.close()
