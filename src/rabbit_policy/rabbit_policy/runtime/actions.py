"""What a policy's 21 numbers mean: the gait directly, or a bounded residual on the library.

* ``direct`` (the paper): the 20 free Bezier coefficients alpha (rad) and Kd (N m s/rad),
  inside :class:`ActionBounds` (the classic gaits' range widened by a margin).
* ``residual`` (the learning issue's ablation row d, after NaviGait 2025): the calibrated
  library's gait interpolated at the commanded speed (what the classic controller runs) plus
  a residual inside +-``scale`` (:data:`RESIDUAL_SCALE`: 0.1 rad on each coefficient, 20
  N m s/rad on Kd), the sum clipped to the direct bounds. A zero residual is the classic
  controller, so training starts exactly from it. With ``integral_gain`` > 0 (1/s) the
  library's gait is the one for ``v_d + integral_gain * I``, I the memory's integral of the
  speed error (:mod:`.speed_integral`: Westervelt's event-based integral), so a zero
  residual is the classic controller with that speed integral. With the ``recovery`` base
  (:data:`RESIDUAL_BASES`) the residual adds to the recovery controller's decision instead
  (:meth:`ResidualAction.compose_on`), so a zero residual is that controller; with
  ``recovery_gated`` the residual is first scaled by the recovery rule's weight w at the
  decision (0 while the hip keeps its pace, up to 1 at the rule's full deficit:
  :func:`residual_gate`), so a policy acts only once something slowed the hip and every
  perturbation of it walks the recovery controller's trajectory until then.

:class:`ResidualAction` is the one implementation, run by the learning environment and by
:class:`~rabbit_policy.runtime.policies.NetworkPolicy` (walk.py, the evaluations, policy_node).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rabbit_hzd_controller.alpha import N_FREE
from rabbit_hzd_controller.controller import ControllerConfig
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.speed_integral import check_gain

ACTIONS = ("direct", "residual")
RESIDUAL_BASES = ("classic", "recovery", "recovery_gated")
"""What a residual adds to: the calibrated library's gait at the command (``classic``), or the
recovery controller's decision (``recovery``: classic plus the push-recovery rule,
:mod:`.recovery`, applied at once; the push-recovery issue's residual on the model-based
baseline)."""
RESIDUAL_SCALE = (0.1,) * N_FREE + (20.0,)
"""Default residual bounds: +-0.1 rad per coefficient, +-20 N m s/rad on Kd."""


def clip(x: np.ndarray, low: np.ndarray | float, high: np.ndarray | float) -> np.ndarray:
    """``np.clip``'s values (NaN stays NaN) as two ufuncs: a third of its call cost, which is
    most of the cost on 21 numbers (a training env step clips a few times)."""
    return np.minimum(np.maximum(x, low), high)


@dataclass(frozen=True)
class ActionBounds:
    """Lower/upper bounds of the 21-dimensional action (20 coefficients in rad, Kd)."""

    low: np.ndarray
    high: np.ndarray

    @classmethod
    def from_library(cls, library: GaitLibrary, margin: float = 0.15,
                     kd_range: tuple[float, float] = (20.0, 150.0),
                     config: ControllerConfig | None = None) -> "ActionBounds":
        config = config or ControllerConfig()
        free = np.array([g.free for g in library.gaits])
        low, high = free.min(axis=0) - margin, free.max(axis=0) + margin
        for i in range(N_FREE):  # output i % 4: hips even, knees odd
            lo, hi = config.knee_coefficient_range if i % 2 else config.hip_coefficient_range
            low[i], high[i] = max(low[i], lo), min(high[i], hi)
        return cls(np.append(low, kd_range[0]), np.append(high, kd_range[1]))

    def to_physical(self, normalised: np.ndarray) -> np.ndarray:
        """The physical action (rad, N m s/rad) of a normalised one, clipped to [-1, 1] first."""
        a = clip(np.asarray(normalised, dtype=float), -1.0, 1.0)
        return self.low + (a + 1.0) * 0.5 * (self.high - self.low)

    def to_normalised(self, physical: np.ndarray) -> np.ndarray:
        """The normalised action in [-1, 1] of a physical one (clipped to the bounds first)."""
        x = clip(np.asarray(physical, dtype=float), self.low, self.high)
        return 2.0 * (x - self.low) / (self.high - self.low) - 1.0


@dataclass(frozen=True)
class ResidualAction:
    """The gait = the library's at the commanded speed + a residual (see the module docstring).

    ``library``: the calibrated library (interpolated); ``direct``: the bounds the sum is
    clipped to; ``scale``: the residual's bounds, +-scale (21: rad, then N m s/rad);
    ``integral_gain``: 1/s on the speed integral the base gait is offset by (0: none)."""

    library: GaitLibrary
    direct: ActionBounds
    scale: tuple[float, ...] = RESIDUAL_SCALE
    integral_gain: float = 0.0

    def __post_init__(self) -> None:
        if len(self.scale) != N_FREE + 1 or not all(s > 0.0 for s in self.scale):
            raise ValueError(f"a residual scale is {N_FREE + 1} numbers > 0, got {self.scale!r}")
        check_gain(self.integral_gain, "the residual's integral gain")

    @property
    def bounds(self) -> ActionBounds:
        """The residual's own bounds (what a network outputs, physical units)."""
        scale = np.asarray(self.scale, dtype=float)
        return ActionBounds(-scale, scale.copy())

    def compose(self, residual: np.ndarray, desired_speed: float, integral: float = 0.0) -> np.ndarray:
        """The physical action (20 coefficients in rad, Kd) for a physical ``residual`` under
        the command ``desired_speed`` (m/s) and the speed integral ``integral`` (m; used
        with ``integral_gain``)."""
        speed = desired_speed + self.integral_gain * integral if self.integral_gain else desired_speed
        gait = self.library.interpolate(speed)
        return self.compose_on(residual, np.append(gait.free, gait.kd))

    def compose_on(self, residual: np.ndarray, base: np.ndarray) -> np.ndarray:
        """The physical action for a physical ``residual`` on the physical action ``base`` (20
        coefficients in rad, Kd; e.g. the recovery controller's decision): their sum, the
        residual within its bounds and the sum within the direct ones."""
        scale = np.asarray(self.scale)
        r = clip(np.asarray(residual, dtype=float), -scale, scale)
        return clip(base + r, self.direct.low, self.direct.high)


def residual_sum_bounds(library: GaitLibrary, base: str = "classic", margin: float = 0.15) -> ActionBounds:
    """What a residual's sum is clipped to (:attr:`ResidualAction.direct`): on the ``classic``
    base the direct action's bounds (the library's range widened by ``margin`` rad); on the
    ``recovery`` bases the controller's own coefficient limits, since the recovery rule's
    offsets reach beyond the library's range (a zero residual must be that controller)."""
    if base not in RESIDUAL_BASES:
        raise ValueError(f"residual base must be one of {RESIDUAL_BASES}, got {base!r}")
    return ActionBounds.from_library(library, margin if base == "classic" else float("inf"))


def residual_gate(base) -> float:
    """What a residual on ``base`` (a residual base's policy, after its decision) is scaled by:
    the recovery rule's weight at that decision for the ``recovery_gated`` base, else 1."""
    return float(base.last_weight) if getattr(base, "gates_residual", False) else 1.0


def policy_bounds(action: str, library: GaitLibrary, margin: float = 0.15) -> ActionBounds:
    """The bounds of what a policy outputs for ``action`` (:data:`ACTIONS`): the gait's, or
    the residual's."""
    if action not in ACTIONS:
        raise ValueError(f"action must be one of {ACTIONS}, got {action!r}")
    direct = ActionBounds.from_library(library, margin)
    return ResidualAction(library, direct).bounds if action == "residual" else direct
