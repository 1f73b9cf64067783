# A forward twin of the recovery rule, probed on the recovery controller (docs/learning.md,
# "2026-11-28 (second)"):
#   .venv/bin/python docs/learning/forward_rule/rule_probe.py scan > docs/learning/forward_rule/rule_scan.json
# The recovery rule acts when the hip falls behind the slowest of the four previous steps at the
# same phase. Its twin here acts when the hip runs ahead of the FASTEST of them by more than
# THRESHOLD (a fraction of the ramped command): w_f = clip(excess / FULL, 0, 1), and w_f x
# offsets (rad) are added to Bezier rows 1-4, at once, as the rule's. Pushed forward at check
# 4's 8 phases at 0.7, 1.0 and 1.3 m/s with 1.3x classic's forward margin (25, 16, 11 N s).
import json
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rabbit_policy.evaluation.robustness import RobustnessConfig, phase_times, push_survived
from rabbit_policy.runtime.policies import make_policy
from rabbit_policy.runtime.recovery import RecoveryPolicy

OUTPUTS = ("stance_hip", "stance_knee", "swing_hip", "swing_knee")
MARGINS = ((0.7, 25), (1.0, 16), (1.3, 11))
FACTOR = 1.3
THRESHOLD, FULL = 0.05, 0.2


class ForwardRule(RecoveryPolicy):
    """The recovery controller with the forward twin added (probe only)."""

    def __init__(self, forward, threshold=THRESHOLD, full=FULL, **kw):
        super().__init__(make_policy("recovery").classic, **kw)
        self.forward = np.zeros((5, 4))
        self.forward[1:, :] = np.asarray(forward)
        self.f_threshold, self.f_full = threshold, full
        self.last_forward = 0.0

    def act(self, observation):
        command = super().act(observation)  # the backward rule (its memory observes here)
        _, _, tau, _, hip_velocity = observation.body
        steps = self.memory.steps[1:]
        b = min(max(int(tau * self.memory.bins), 0), self.memory.bins - 1)
        refs = []
        for step in steps:
            known = np.flatnonzero(~np.isnan(step[:, 0]))
            if known.size < self.memory.bins // 2:
                refs = []
                break
            v, then = step[known[np.argmin(np.abs(known - b))]]
            refs.append(v / max(then, 0.1))
        ramped = max(self._base.command, 0.1)
        w = 0.0
        if refs and 0.0 < tau < 1.0 and self.last_weight == 0.0:
            excess = hip_velocity / ramped - max(refs) - self.f_threshold
            w = min(max(excess / self.f_full, 0.0), 1.0)
        self.last_forward = w
        if w <= 0.0:
            return command
        from rabbit_hzd_controller.alpha import expand_alpha, reduce_alpha
        from rabbit_policy.runtime.policies import GaitCommand
        free = reduce_alpha(command.alpha).reshape(5, 4) + w * self.forward
        return GaitCommand(tuple(float(v) for v in expand_alpha(free.reshape(20))), command.kd)


def cases(policy):
    out = []
    for speed, margin in MARGINS:
        for t in phase_times(policy, speed, 3.0, [i / 8 for i in range(8)]):
            out.append((speed, t, float(np.ceil(FACTOR * margin))))
    return out


def score(args):
    forward, threshold, full = args
    policy = ForwardRule(forward, threshold, full)
    config = RobustnessConfig()
    ok = [push_survived((policy, s, t, i, config)) for s, t, i in CASES]
    return ok


CASES = cases(make_policy("recovery"))


def main() -> None:
    combos = [((0, 0, 0, 0), THRESHOLD, FULL)]
    for k in range(4):
        for value in (-0.15, 0.15):
            v = [0.0] * 4
            v[k] = value
            combos.append((tuple(v), THRESHOLD, FULL))
    with ProcessPoolExecutor(2) as pool:
        results = list(pool.map(score, combos))
    rows = [{"offsets": c[0], "survived": int(sum(r)), "by_speed": [int(sum(r[8 * i:8 * i + 8])) for i in range(3)]}
            for c, r in zip(combos, results)]
    print(json.dumps({"impulses": [float(np.ceil(FACTOR * m)) for _, m in MARGINS], "threshold": THRESHOLD,
                      "full": FULL, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
