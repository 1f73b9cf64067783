# After one push the recovery rule is blind to the next for four steps: its reference at each
# phase is the slowest of the four previous steps, and the pushed step is one of them. Probe: a
# step in which the rule acted (w > 0 at any decision) is not kept in the memory (the memory keeps
# the steps before it). docs/learning.md "2026-11-28 (second)".
# With LEVEL, only a step in which w exceeded LEVEL is left out (the learned walk's near-stall
# steps at 0.7-0.8 m/s stir the rule below 0.5; left out, the memory goes stale).
#   .venv/bin/python docs/learning/repeated_pushes/memory_probe.py [skip|base] [LEVEL] > ...
# (Run on the package of 08abeef, whose memory kept every step: "skip" here is the probe's own rule.
# On a later package, which forgets itself, "skip" would stack two rules: read repeated.txt.)
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rabbit_policy.runtime import recovery as R
from rabbit_policy.runtime.body import touched_down

MODE = sys.argv[1] if len(sys.argv) > 1 else "skip"
LEVEL = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0  # drop the step if w exceeded this


class SkippingMemory(R.StepMemory):
    def reset(self):
        super().reset()
        self.acted = False

    def observe(self, tau, hip_velocity, command):
        if touched_down(self._last_tau, tau):
            if self.acted:  # drop the step the rule acted in
                self.steps[0] = np.full((self.bins, 2), np.nan)
                self._last_tau = None  # no shift below
                self.acted = False
        return super().observe(tau, hip_velocity, command)


_act = R.RecoveryPolicy.act


def act(self, observation):
    command = _act(self, observation)
    if self.last_weight > LEVEL:
        self.memory.acted = True
    return command


if MODE == "skip":
    R.StepMemory = SkippingMemory
    R.RecoveryPolicy.act = act


def main():
    from rabbit_policy.evaluation.push_recovery import PushScenario, push_trial
    from rabbit_policy.evaluation.robustness import RobustnessConfig, push_margin
    from rabbit_policy.runtime.policies import make_policy

    for kind in ("recovery", "learned"):
        for impulse in (-13.0, -22.0):
            r = push_trial(make_policy(kind), 1.0, PushScenario("s", impulse / 0.1))
            print(MODE, kind, f"scenario {impulse} x3 at 2/4/6 s:", "fell/stalled" if r.failed else "walks",
                  " ".join(f"{s:.2f}:{v:.2f}" for s, e, v in r.step_speeds()), flush=True)
    with ProcessPoolExecutor(2) as pool:
        for kind in ("recovery", "learned"):
            row = [push_margin(make_policy(kind), s, -1, RobustnessConfig(), pool.map)["largest_survived_Ns"]
                   for s in (0.7, 1.0, 1.3)]
            print(MODE, kind, "backward margins 0.7 · 1.0 · 1.3:", row, flush=True)


if __name__ == "__main__":
    main()
