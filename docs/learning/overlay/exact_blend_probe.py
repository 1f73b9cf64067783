# Probe (docs/learning.md, 2026-11-28): the policy blend with the controller's blend followed exactly in alpha.
# The package's policy blend (RecoveryOverlay.blended) restarts a smoothstep from rest at every decision: over
# 20 ticks (0.03 of phase at 0.7 m/s) it moves 6 % of the way, so the network's gaits come in about 3x slower
# than under the controller, whose blend restarted by apply_now keeps the rate of the blend in progress
# (law._start_blend: offsets and rates matched). Here the overlay keeps the controller's blend state in alpha
# (outputs are linear in alpha): at each decision before 0.6 of phase a new blend starts from the blended gait
# and its rate (per unit of phase); from 0.6 the new gait (and its Kd) waits for the touchdown, which starts a
# blend from the old gait, positions only. The gait for the next 20 ticks is the blend at the middle of them.
# Optionally with the late freeze (late_freeze_probe.py). Run on the package's first policy blend (commit 49f2f67's
# parent); the package's AlphaBlend (since 49f2f67) is this class's blend and gives the same figures.
#   .venv/bin/python docs/learning/overlay/policy_blend.py src/rabbit_policy/rabbit_policy/trained/hzd_rl_policy.pt none
#   .venv/bin/python docs/learning/overlay/exact_blend_probe.py LATE [back fwd transitions random]   (LATE 1: no freeze)
import sys
from dataclasses import replace

import numpy as np

sys.argv.insert(2, "0")  # no fast hold for the late freeze probe's class
_src = open("docs/learning/overlay/late_freeze_probe.py").read().split("\npolicy = LearnedPolicy")[0]
_ns: dict = {}
exec(_src, _ns)
del sys.argv[2]

from rabbit_hzd_controller.law import blend_shape
from rabbit_policy.evaluation.robustness import RobustnessConfig, push_margin, random_sequences, transitions
from rabbit_policy.parallel import LocalBackend
from rabbit_policy.runtime.policies import GaitCommand, LearnedPolicy

LATE = float(sys.argv[1])
BLEND, UNTIL, PERIOD_S = 0.2, 0.6, 0.02  # the controller's defaults, 20 ticks


class ExactBlendOverlay(_ns["LateFreezeOverlay"]):
    def reset(self) -> None:
        super().reset()
        self._target = self._off = self._rate = self._pending = None
        self._start_phase = 0.0
        self._kd = None
        self._pending_kd = None
        self._last_tau = None

    def start(self, command) -> None:
        self._target = np.asarray(command.alpha, dtype=float)
        self._off = np.zeros_like(self._target)
        self._rate = np.zeros_like(self._target)
        self._start_phase = 0.0
        self._kd = command.kd

    def _at(self, tau):
        w, dw, h, dh = blend_shape((tau - self._start_phase) / BLEND, BLEND)
        return self._target + self._off * w + self._rate * h, self._off * dw + self._rate * dh

    def blended(self, observation, command):
        _, _, tau, tau_rate, _ = observation.body
        new = np.asarray(command.alpha, dtype=float)
        if self._target is None:
            self.start(command)
        if self._last_tau is not None and tau < self._last_tau - 0.5 and self._pending is not None:
            old, _ = self._at(1.0)
            self._off, self._rate = self._target - self._pending, np.zeros_like(new)  # the law drops the blend in progress
            self._target, self._start_phase, self._pending = self._pending, 0.0, None
            if self._pending_kd is not None:
                self._kd, self._pending_kd = self._pending_kd, None
        self._last_tau = tau
        if 0.0 <= tau < UNTIL:
            self._pending = self._pending_kd = None
            if not np.array_equal(new, self._target):
                now, rate = self._at(tau)
                self._off, self._rate = now - new, (rate if 0.0 < tau < 1.0 else np.zeros_like(new))
                self._target, self._start_phase = new, tau
            self._kd = command.kd
        else:
            self._pending, self._pending_kd = new, command.kd
        mid, _ = self._at(tau + 0.5 * max(tau_rate, 0.0) * PERIOD_S)
        return GaitCommand(tuple(float(v) for v in mid), self._kd)


if __name__ == "__main__":
    policy = LearnedPolicy("/tmp/policy_blend_overlay.pt")
    policy.overlay.__class__ = ExactBlendOverlay
    policy.overlay.reset()
    what = sys.argv[2:] or ["back", "fwd"]
    config = replace(RobustnessConfig(), max_impulse=30)
    backend = LocalBackend(2)
    tag = f"exact blend, late freeze {LATE}"
    for d, name in ((-1, "back"), (1, "fwd")):
        if name in what:
            for v in config.push_speeds:
                m = push_margin(policy, v, d, config, backend.map)
                print(tag, name, v, m["largest_survived_Ns"], m["first_failing_phases"], flush=True)
    if "transitions" in what:
        t = transitions(policy, config, backend.map)
        print(tag, "ordered changes", t["passed"], "of", t["total"], "fell or stalled", t["fell_or_stalled"],
              [(p["from"], p["to"]) for p in t["pairs"] if p["fell_or_stalled"]], flush=True)
    if "random" in what:
        r = random_sequences(policy, config, backend.map)
        print(tag, "random", r["passed"], "of", r["total"], flush=True)
    backend.close()
