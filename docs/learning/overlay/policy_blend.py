"""Probe (docs/learning.md, 2026-11-27 (eighth)): the controller applies gaits at once, and the policy
itself blends the network's gait in, as the controller would (so the rule's offsets act at once and
the network's own gait changes stay smooth).

The controller's blend (``ControllerConfig.within_step_blend`` 0.2, ``within_step_until`` 0.6): every
new gait starts from the outputs in force and reaches the new gait's over 0.2 of phase (smoothstep);
from 0.6 of phase a new gait waits for the touchdown. The outputs are linear in alpha, so the same
blend in alpha at the decisions (every 20 ticks) is that blend sampled: the gait for the next 20
ticks is ``applied + s(dtau / 0.2) (network - applied)`` (dtau: the phase rate x 20 ms), and from
0.6 of phase ``applied`` is held until the touchdown. The rule of RecoveryOverlay (fast gate 0.1,
hold 0.5) then adds its offsets to ``applied``, at once.

    .venv/bin/python docs/learning/overlay/policy_blend.py POLICY.pt [what...]   (what: back fwd transitions random models)
(the measure runs the package's OverlayConfig(at_once=True, policy_blend=True) on POLICY's network)
"""
from __future__ import annotations

import sys
from dataclasses import replace

import numpy as np

from rabbit_policy.runtime.network import PolicyCheckpoint
from rabbit_policy.runtime.policies import GaitCommand, LearnedPolicy
from rabbit_policy.runtime.recovery import CONTROLLER_SETTINGS, OverlayConfig, RecoveryOverlay


def smoothstep(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


class PolicyBlend:
    needs_body = True
    controller_settings = CONTROLLER_SETTINGS

    def __init__(self, policy_file: str, blend: float = 0.2, until: float = 0.6, rule: bool = True) -> None:
        checkpoint = PolicyCheckpoint.load(policy_file)
        checkpoint.info.pop("recovery_overlay", None)
        plain = "/tmp/policy_blend_plain.pt"
        checkpoint.save(plain)
        self.learned = LearnedPolicy(plain)
        self.overlay = RecoveryOverlay(OverlayConfig()) if rule else None
        self.blend, self.until = blend, until
        self.decision_period = self.learned.decision_period
        self.decision_window = self.learned.decision_window
        self.name = f"policy-blend(blend={blend}, until={until}, rule={rule})"
        self._applied = None

    def reset(self) -> None:
        self.learned.reset()
        if self.overlay is not None:
            self.overlay.reset()
        self._applied = None

    def start_command(self, speed: float) -> GaitCommand:
        command = self.learned.start_command(speed)
        self._applied = np.asarray(command.alpha)
        return command

    def act(self, observation) -> GaitCommand:
        network = self.learned.act(observation)
        _, _, tau, tau_rate, _ = observation.body
        target = np.asarray(network.alpha)
        if self._applied is None:
            self._applied = target
        elif 0.0 <= tau < self.until:
            dtau = max(tau_rate, 0.0) * 0.02
            self._applied = self._applied + smoothstep(dtau / self.blend) * (target - self._applied)
        command = GaitCommand(tuple(float(v) for v in self._applied), network.kd)
        return command if self.overlay is None else self.overlay.apply(observation, command)


if __name__ == "__main__":
    # The package's implementation (OverlayConfig(at_once=True, policy_blend=True), written by
    # ship_policy.with_recovery_overlay on the network without its overlay); PolicyBlend above is the
    # probe class it was first measured with (policy_blend_probe_class.txt; its smoothstep rounds
    # differently from the controller's blend_shape the package reuses).
    import importlib.util

    from rabbit_policy.evaluation.acceptance import BroadCriteria
    from rabbit_policy.evaluation.robustness import (RobustnessConfig, model_errors, push_margin, random_sequences,
                                                     transitions)
    from rabbit_policy.parallel import LocalBackend

    spec = importlib.util.spec_from_file_location("ship_policy", "scripts/ship_policy.py")
    ship = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ship)
    checkpoint = PolicyCheckpoint.load(sys.argv[1])
    checkpoint.info.pop("recovery_overlay", None)
    checkpoint.save("/tmp/policy_blend_plain.pt")
    path = ship.with_recovery_overlay("/tmp/policy_blend_plain.pt", "/tmp/policy_blend_overlay.pt", policy_blend=True)
    policy = LearnedPolicy(path)
    what = sys.argv[2:] or ["back", "fwd", "transitions", "random", "models"]
    config = replace(RobustnessConfig(), max_impulse=30)
    backend = LocalBackend(2)
    tag = f"{policy.name} {policy.checkpoint.info['recovery_overlay']}"
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
    if "models" in what:
        rows = model_errors(policy, config, backend.map)["rows"]
        judged = BroadCriteria().judged_models
        print(tag, "judged", sum(r["passed"] for r in rows if r["case"] in judged), flush=True)
    backend.close()
