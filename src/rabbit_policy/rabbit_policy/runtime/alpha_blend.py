"""A policy's own gaits blended in alpha, as the controller's defaults blend and queue them.

A controller run with gaits applied at once (``within_step_blend`` 0, the recovery settings)
takes each gait as it comes. A policy that wants its own gaits to come in smoothly, as under
the controller's defaults (blended over ``within_step_blend`` = 0.2 of phase, queued for the
touchdown from ``within_step_until`` = 0.6), while something it adds acts at once (the
recovery rule's offsets, :class:`~.recovery.RecoveryOverlay`), blends them itself with
:class:`AlphaBlend`:

* a new gait before ``until`` starts a blend from the blended gait in force A and its rate
  dA/dtau (per unit of phase): A(tau) = new + O w(r) + R h(r), O and R the offset and rate
  at the start, r the phase since the start over the length, w and h the controller's
  ``blend_shape`` (1 - smoothstep, and ``length r (1 - r)^2``). So alpha and its rate stay
  continuous when a new gait restarts the blend at every decision, and the new gait is
  reached within the length;
* from ``until`` a new gait and its Kd wait for the touchdown, which starts a blend from the
  gait it replaces, at rest, from phase 0;
* the gait :meth:`AlphaBlend.step` returns for the next decision period is the blend at the
  middle of the phase that period advances (the phase rate x the period).

This is the controller's blend carried to the coefficients, not the same arithmetic: the
controller (``rabbit_hzd_controller.law``) freezes the outputs' offset (rad) and rate at the
blend's start and decays them, while here the offset is the two gaits' difference, which
moves along the phase. Both reach the new gait's outputs within the length with the outputs
and their rates continuous.

Why the rate (docs/learning.md 2026-11-28): the first version (until 2026-11-28) restarted a
smoothstep from rest at every decision, which moves 6 % of the way in 20 ticks at 0.7 m/s
(0.03 of phase, 0.15 of the blend): the network's gaits came in about 3x slower than under
the controller, and its forward push margin at 0.7 m/s was 18 N s; with this blend, 24.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rabbit_hzd_controller.law import blend_shape
from rabbit_policy.runtime.body import touched_down


@dataclass(frozen=True)
class BlendConfig:
    """An alpha blend's constants (a controller spec's ``blend`` section, read straight into
    this class): ``length``, the phase the blend takes; ``until``, the phase from which a new
    gait is queued for the touchdown. Both in (0, 1]."""

    length: float
    until: float

    def __post_init__(self) -> None:
        if not (0.0 < self.length <= 1.0 and 0.0 < self.until <= 1.0):
            raise ValueError(f"an alpha blend needs a length and until in (0, 1], got {self.length}, {self.until}")


class AlphaBlend:
    """The blend state in alpha: the gait blended into (``target``), the offsets from it at the
    blend's start (rad) and their rate (rad per unit of phase), the start phase; the gait and
    Kd queued for the touchdown. ``config``: its length and until (:class:`BlendConfig`);
    ``period_s``: the time a returned gait is held (s)."""

    def __init__(self, config: BlendConfig, period_s: float) -> None:
        if not period_s > 0.0:
            raise ValueError(f"AlphaBlend needs a period > 0 s, got {period_s}")
        self.length, self.until, self.period_s = config.length, config.until, period_s
        self.target: np.ndarray | None = None

    def reset(self) -> None:
        """Before a walk: no gait in force until :meth:`start` (or the first :meth:`step`)."""
        self.target = None

    def start(self, alpha, kd: float) -> None:
        """The gait (alpha, rad; Kd, N m s/rad) the walk starts on: in force, no blend."""
        self.target = np.asarray(alpha, dtype=float)
        self._offset = np.zeros_like(self.target)
        self._rate = np.zeros_like(self.target)
        self._start = 0.0
        self.kd = kd
        self._queued: tuple[np.ndarray, float] | None = None
        self._last_tau: float | None = None

    def at(self, tau: float) -> tuple[np.ndarray, np.ndarray]:
        """The blended alpha at phase ``tau`` and its rate (per unit of phase)."""
        w, dw, h, dh = blend_shape((tau - self._start) / self.length, self.length)
        return self.target + self._offset * w + self._rate * h, self._offset * dw + self._rate * dh

    def step(self, tau: float, tau_rate: float, alpha, kd: float) -> tuple[np.ndarray, float]:
        """A decision at phase ``tau`` (rate ``tau_rate``, 1/s) asking for ``alpha`` and ``kd``:
        the gait (alpha, Kd) to hold for the next period. A touchdown (the phase falling back by
        more than half a step) brings in what was queued."""
        new = np.asarray(alpha, dtype=float)
        if self.target is None:
            self.start(new, kd)
        if touched_down(self._last_tau, tau) and self._queued is not None:
            queued, self.kd = self._queued
            self._offset, self._rate = self.target - queued, np.zeros_like(queued)  # the blend in progress is dropped
            self.target, self._start, self._queued = queued, 0.0, None
        self._last_tau = tau
        if 0.0 <= tau < self.until:
            self._queued = None
            if not np.array_equal(new, self.target):
                now, rate = self.at(tau)
                self._offset, self._rate = now - new, rate if tau > 0.0 else np.zeros_like(new)
                self.target, self._start = new, tau
            self.kd = kd
        else:
            self._queued = (new, kd)
        held, _ = self.at(tau + 0.5 * max(tau_rate, 0.0) * self.period_s)
        return held, self.kd
