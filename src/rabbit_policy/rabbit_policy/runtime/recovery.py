"""The model-based push-recovery baseline, ``recovery``: classic HZD plus a hand-designed
rule that acts within the step when the hip falls behind its gait.

Why this rule (docs/learning.md, "Push recovery: ceilings and a model-based baseline"):
classic HZD's backward failures end in the first stance after the push. The hip stops short
of the stance foot, the phase stalls and the robot rocks back (a stall, not a fall), and a
new gait queued for the next touchdown never lands. The ceiling study found that gaits
applied at once, inside that stance, reach far beyond classic's margin, and a scan of single
directions found one that rescues most pushes: **bend the stance knee and swing the swing
leg forward** over the middle of the step (Bezier rows 1-4, so the step's start and end
postures, and the impact equalities, stay as they are).

The rule, every 20 ticks (as classic decides), from the body state (:mod:`.body`):

1. the hip's deficit d = (v_nom(v_bar, tau) - v_x) / v_bar - ``threshold``, where v_bar is
   the mean hip speed over the last step's duration (the observation's, m/s), and v_nom the
   hip velocity (m/s, world x) that classic's gait for v_bar has at this phase tau when it
   walks undisturbed (:class:`HipSpeedProfile`, calibrated by walking each gait:
   :func:`rabbit_policy.gait_design.calibration.calibrate_hip_profile`). The reference is
   the speed the robot walks at, not the command, so a commanded speed-up is not taken
   for a push;
2. w = clip(d / ``full``, 0, 1) while the phase is inside the step (0 < tau < 1: at its
   ends the hip phase is clamped and says nothing of the hip's progress), else 0;
3. the gait is classic's with ``w * offsets`` (rad) added to rows 1-4 of the four outputs
   (stance hip, stance knee, swing hip, swing knee), applied at once: no blend, no queue
   (:data:`CONTROLLER_SETTINGS`, which the loops and the stack give the controller).
   Classic's gait is the library's for the command rate-limited to ``command_rate`` m/s per
   decision: applied at once, a library gait that jumps with the command made 12 of 72
   ordered speed changes fall or stall (decelerations from 1.4-1.5 m/s at the start of a
   step); a ramp of 0.5 m/s per second made none of those fail.

Undisturbed, w stays 0 and the gait is classic's (the limit cycle is classic's). The rule
never speeds up: a forward push (the hip ahead of its gait) leaves classic alone.
"""

from __future__ import annotations

import json
from bisect import bisect_left
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rabbit_hzd_controller.alpha import N_FREE, N_OUTPUTS, expand_alpha, reduce_alpha
from rabbit_policy.runtime.gait_library import PROFILE_FILE, GaitLibrary
from rabbit_policy.runtime.speed_window import Observation

CONTROLLER_SETTINGS = {"within_step_blend": 0.0, "within_step_until": 1.0, "blend_phase": 0.0}
"""The controller settings this controller needs (``ControllerConfig`` fields): a gait
applies from the next tick, within the step, not blended in and never queued."""


@dataclass(frozen=True)
class RecoveryConfig:
    """The rule's constants (see the module docstring).

    offsets: rad added to Bezier rows 1-4 of (stance hip, stance knee, swing hip, swing
        knee) at full deficit (w = 1).
    threshold: the deficit (fraction of v_d) below which nothing is done.
    full: the deficit beyond the threshold (fraction of v_d) at which w reaches 1.
    command_rate: m/s per decision (20 ticks) the base gait's speed follows the command by.
    """

    offsets: tuple[float, float, float, float] = (-0.11, 0.01, 0.08, -0.23)
    threshold: float = 0.1
    full: float = 0.24
    command_rate: float = 0.01

    def __post_init__(self) -> None:
        if len(self.offsets) != N_OUTPUTS or not all(np.isfinite(self.offsets)):
            raise ValueError(f"RecoveryConfig.offsets must be {N_OUTPUTS} finite numbers (rad), got {self.offsets!r}")
        if not (np.isfinite(self.threshold) and self.threshold >= 0.0):
            raise ValueError(f"RecoveryConfig.threshold must be finite and >= 0, got {self.threshold}")
        if not (np.isfinite(self.full) and self.full > 0.0):
            raise ValueError(f"RecoveryConfig.full must be finite and > 0, got {self.full}")
        if not (np.isfinite(self.command_rate) and self.command_rate > 0.0):
            raise ValueError(f"RecoveryConfig.command_rate must be finite and > 0 m/s, got {self.command_rate}")


@dataclass(frozen=True)
class HipSpeedProfile:
    """The undisturbed hip velocity (m/s, world x) of the library's gaits by phase:
    ``table[i][b]`` at ``speeds[i]`` (m/s, commanded) in phase bin b of ``len(table[i])``
    equal bins over [0, 1]."""

    speeds: tuple[float, ...]
    table: tuple[tuple[float, ...], ...]

    def __post_init__(self) -> None:
        if len(self.speeds) < 1 or len(self.speeds) != len(self.table):
            raise ValueError("a hip speed profile needs one row per speed, at least one")
        if list(self.speeds) != sorted(set(self.speeds)):
            raise ValueError("a hip speed profile's speeds must increase")
        bins = {len(row) for row in self.table}
        if len(bins) != 1 or bins.pop() < 2:
            raise ValueError("every row of a hip speed profile has the same number (>= 2) of phase bins")
        if not all(np.isfinite(v) for row in self.table for v in row):
            raise ValueError("a hip speed profile's entries must be finite")

    def nominal(self, speed: float, tau: float) -> float:
        """v_nom (m/s) at commanded ``speed`` (clamped to the profile's speeds) and phase
        ``tau`` (clamped to [0, 1]): linear in speed between rows, and in phase between
        bin centres."""
        table = np.asarray(self.table)
        bins = table.shape[1]
        centres = (np.arange(bins) + 0.5) / bins
        speeds = self.speeds
        if speed <= speeds[0]:
            row = table[0]
        elif speed >= speeds[-1]:
            row = table[-1]
        else:
            i = bisect_left(speeds, speed)
            w = (speed - speeds[i - 1]) / (speeds[i] - speeds[i - 1])
            row = (1.0 - w) * table[i - 1] + w * table[i]
        return float(np.interp(min(max(tau, 0.0), 1.0), centres, row))

    def to_dict(self) -> dict:
        return {"speeds": list(self.speeds), "table": [[round(v, 5) for v in r] for r in self.table],
                "units": "m/s, hip velocity along world x; rows: commanded speed; columns: equal phase bins"}

    @classmethod
    def from_dict(cls, data: dict) -> "HipSpeedProfile":
        return cls(tuple(float(v) for v in data["speeds"]), tuple(tuple(float(v) for v in r) for r in data["table"]))

    @classmethod
    def load(cls, directory: str | Path) -> "HipSpeedProfile":
        """The profile in ``directory`` (a gait library's); raises ``FileNotFoundError`` or
        ``ValueError`` saying what to do."""
        path = Path(directory) / PROFILE_FILE
        if not path.is_file():
            raise FileNotFoundError(f"no {PROFILE_FILE} in {directory}: run scripts/calibrate_library.py "
                                    f"--hip-profile for this library")
        try:
            return cls.from_dict(json.loads(path.read_text()))
        except (TypeError, ValueError, KeyError, AttributeError) as exc:
            raise ValueError(f"{path} is not a hip speed profile ({str(exc)[:160]})") from None


class RecoveryPolicy:
    """Classic HZD (the library's gait for v_d, every 20 ticks) plus the recovery rule (the
    module docstring). ``classic`` is the library policy it adds to; ``needs_body``: it reads
    ``observation.body``; ``controller_settings``: what the controller must run with."""

    needs_body = True
    controller_settings = CONTROLLER_SETTINGS

    def __init__(self, classic, library: GaitLibrary, profile: HipSpeedProfile,
                 config: RecoveryConfig = RecoveryConfig(), decision_period: int = 20,
                 decision_window: int = 1000) -> None:
        from rabbit_policy.runtime.policies import RateLimitedPolicy

        self.classic = classic
        self._base = RateLimitedPolicy(classic, config.command_rate)
        self.library = library
        self.profile = profile
        self.config = config
        self.decision_period = decision_period
        self.decision_window = decision_window
        self.name = f"recovery@{decision_period}ticks"
        self._offsets = np.zeros((5, N_OUTPUTS))
        self._offsets[1:, :] = np.asarray(config.offsets)

    def with_config(self, config: RecoveryConfig) -> "RecoveryPolicy":
        """The same controller with other constants (tuning)."""
        return RecoveryPolicy(self.classic, self.library, self.profile, config, self.decision_period,
                              self.decision_window)

    def reset(self) -> None:
        self._base.reset()

    def start_command(self, speed: float):
        """Classic's gait at ``speed`` (no body state exists before the walk)."""
        return self.classic.act(Observation(speed, speed, 0.0))

    def weight(self, mean_speed: float, tau: float, hip_velocity: float) -> float:
        """w in [0, 1]: how much of the offsets apply (see the module docstring); ``mean_speed``
        (m/s) is clamped to the profile's speeds."""
        if not 0.0 < tau < 1.0:
            return 0.0
        low, high = self.profile.speeds[0], self.profile.speeds[-1]
        reference = min(max(mean_speed, low), high)
        deficit = (self.profile.nominal(reference, tau) - hip_velocity) / reference - self.config.threshold
        return min(max(deficit / self.config.full, 0.0), 1.0)

    def act(self, observation: Observation):
        from rabbit_policy.runtime.policies import GaitCommand

        command = self._base.act(observation)
        if observation.body is None:
            raise ValueError("the recovery controller needs the body state (observation.body)")
        _, _, tau, _, hip_velocity = observation.body
        w = self.weight(observation.mean_speed, tau, hip_velocity)
        if w <= 0.0:
            return command
        free = reduce_alpha(command.alpha).reshape(5, N_OUTPUTS) + w * self._offsets
        return GaitCommand(tuple(float(v) for v in expand_alpha(free.reshape(N_FREE))), command.kd)
