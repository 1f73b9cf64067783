"""Probe (docs/learning.md, 2026-11-27 (eighth)): the recovery controller's rule on top of the shipped
learned policy. The network decides as shipped (its residual on classic + its speed integral); the
recovery rule (rabbit_policy.runtime.recovery, its constants and its deceleration gate, reading a
classic RecoveryPolicy run beside it for its weight only) adds w x its offsets to the network's
gait, and the controller applies gaits at once (the recovery controller's settings).
``rule=False``: the network alone, applied at once (what the controller settings alone change).
``fast_gate`` > 0: the rule is held off while the hip's mean speed over the policy's window (1 s)
exceeds the command by more than that fraction (after a forward push the first stance of a long,
fast step looks like a backward push's deficit to the rule). ``handover``: instead of adding w x
offsets to the network's gait, hand over to the recovery controller in proportion to w:
(1 - w) x the network's gait + w x the recovery controller's (its base gait plus w x offsets).
``hold`` > 0: while w >= hold the network's gait is the one it chose at the last decision with w = 0
(the network still sees every observation, its memory moves on), plus w x offsets.
``blended``: the controller blends every gait in as the shipped network's (no at-once settings)."""
from __future__ import annotations

import numpy as np

from rabbit_hzd_controller.alpha import N_FREE, expand_alpha, reduce_alpha
from rabbit_policy.runtime.policies import GaitCommand, LearnedPolicy, make_policy, packaged_policy_file
from rabbit_policy.runtime.recovery import CONTROLLER_SETTINGS, N_OUTPUTS, RecoveryPolicy


class RuleOnLearned:
    needs_body = True
    controller_settings = CONTROLLER_SETTINGS

    def __init__(self, policy_file=None, rule: bool = True, scale: float = 1.0, fast_gate: float = 0.0,
                 handover: bool = False, hold: float = 0.0, blended: bool = False) -> None:
        self.learned = LearnedPolicy(policy_file or packaged_policy_file())
        self.recovery = make_policy("recovery")
        assert isinstance(self.recovery, RecoveryPolicy)
        self.rule, self.scale, self.fast_gate, self.handover, self.hold = rule, scale, fast_gate, handover, hold
        self._held = None
        if blended:  # the controller's defaults: the network's gait (and the offsets) blended in, late ones queued
            self.controller_settings = {}
        self.decision_period = self.learned.decision_period
        self.decision_window = self.learned.decision_window
        self.name = f"rule-on-learned(rule={rule}, scale={scale}, fast_gate={fast_gate}, handover={handover}, hold={hold}, blended={blended})"

    def reset(self) -> None:
        self._held = None
        self.learned.reset()
        self.recovery.reset()

    def start_command(self, speed: float) -> GaitCommand:
        self.recovery.start_command(speed)
        return self.learned.start_command(speed)

    def act(self, observation) -> GaitCommand:
        command = self.learned.act(observation)
        recovery = self.recovery.act(observation)  # its memory, ramp and weight
        w = self.recovery.last_weight * self.scale if self.rule else 0.0
        if self.fast_gate > 0.0 and observation.mean_speed > observation.desired_speed * (1.0 + self.fast_gate):
            w = 0.0
        if w <= 0.0:
            self._held = command
            return command
        if self.hold > 0.0 and w >= self.hold and self._held is not None:
            command = self._held
        if self.handover:
            mixed = (1.0 - w) * np.asarray(command.alpha) + w * np.asarray(recovery.alpha)
            return GaitCommand(tuple(float(v) for v in mixed), (1.0 - w) * command.kd + w * recovery.kd)
        free = reduce_alpha(command.alpha).reshape(5, N_OUTPUTS) + w * self.recovery._offsets
        return GaitCommand(tuple(float(v) for v in expand_alpha(free.reshape(N_FREE))), command.kd)
