"""Linear stability of a periodic motion from its return map (Poincaré map), numerically.

A periodic walk crosses a Poincaré section (e.g. the touchdown) once per step; the
return map P takes the state at one crossing to the state at the next, and the walking
cycle is a fixed point x* = P(x*). The cycle is locally exponentially stable when every
eigenvalue of the Jacobian DP(x*) lies inside the unit circle; the largest magnitude is
the factor by which a perturbation shrinks per step.

This module is model-free: ``step`` is any callable ``x -> P(x)`` on numpy vectors (for
RABBIT: restore the full simulator state, apply the perturbed coordinates, simulate one
step). :func:`section_crossing` interpolates the crossing between two samples of a
time-stepped simulation, so that the sampled map is continuous in the state (a crossing
taken at the first sample past the section jumps by a whole timestep when a
perturbation moves it across a sample). Tested on maps with known eigenvalues before it
is trusted on the robot.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

ReturnMap = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class PoincareAnalysis:
    """Fixed point, its residual |P(x*) - x*| and the Jacobian DP(x*)."""

    fixed_point: np.ndarray
    residual: float
    jacobian: np.ndarray

    @property
    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of DP(x*), largest magnitude first."""
        values = np.linalg.eigvals(self.jacobian)
        return values[np.argsort(-np.abs(values), kind="stable")]

    @property
    def magnitudes(self) -> np.ndarray:
        return np.abs(self.eigenvalues)

    @property
    def stable(self) -> bool:
        """All |lambda| < 1."""
        return bool(self.magnitudes.max() < 1.0)

    def to_dict(self) -> dict:
        return {"magnitudes": self.magnitudes.tolist(), "largest": float(self.magnitudes.max()),
                "stable": self.stable, "residual": self.residual, "dimension": int(len(self.fixed_point))}


def finite_difference_jacobian(step: ReturnMap, x: np.ndarray, delta: float | np.ndarray) -> np.ndarray:
    """DP(x) by central differences: column i = (P(x + d_i e_i) - P(x - d_i e_i)) / 2 d_i."""
    x = np.asarray(x, dtype=float)
    deltas = np.broadcast_to(np.asarray(delta, dtype=float), x.shape)
    if np.any(deltas <= 0):
        raise ValueError("finite-difference steps must be > 0")
    columns = []
    for i, d in enumerate(deltas):
        e = np.zeros_like(x)
        e[i] = d
        columns.append((np.asarray(step(x + e)) - np.asarray(step(x - e))) / (2.0 * d))
    return np.column_stack(columns)


@dataclass(frozen=True)
class RegressionFit:
    """A least-squares Jacobian and how many perturbation pairs went into it (``used``)
    or were dropped because the map failed on them (``failed``)."""

    jacobian: np.ndarray
    used: int
    failed: int


def regression_fit(step: ReturnMap, x: np.ndarray, scale: float | np.ndarray, samples: int | None = None,
                   seed: int = 0, skip: tuple[type[BaseException], ...] = ()) -> RegressionFit:
    """DP(x) by least squares over random symmetric perturbations d_k ~ N(0, diag(scale^2)):
    the J minimising sum_k |P(x + d_k) - P(x - d_k) - 2 J d_k|^2 (``samples`` pairs,
    default 4 n). A pair on which ``step`` raises one of ``skip`` (a walk that fell) is
    dropped and counted.

    For a map that is only piecewise smooth at a fine grain — a simulation sampled at a
    fixed timestep, where a perturbation that moves an event (a touchdown switch) across
    a sample boundary makes the state jump — central differences with a tiny step see the
    jump divided by the step; perturbations of a moderate ``scale`` spread over many
    samples average such jumps into the map's mean slope."""
    x = np.asarray(x, dtype=float)
    n = len(x)
    scales = np.broadcast_to(np.asarray(scale, dtype=float), x.shape)
    if np.any(scales <= 0):
        raise ValueError("perturbation scales must be > 0")
    rng = np.random.default_rng(seed)
    count = samples or 4 * n
    if count < n:
        raise ValueError(f"need at least {n} samples for a {n}-dimensional map")
    d = rng.standard_normal((count, n)) * scales
    kept, y = [], []
    for dk in d:
        try:
            y.append(np.asarray(step(x + dk)) - np.asarray(step(x - dk)))
        except skip:
            continue
        kept.append(dk)
    if len(kept) < n:
        raise RuntimeError(f"only {len(kept)} of {count} perturbation pairs succeeded; need {n}")
    solution, *_ = np.linalg.lstsq(2.0 * np.array(kept), np.array(y), rcond=None)  # (2 d) J^T = y
    return RegressionFit(solution.T, len(kept), count - len(kept))


def regression_jacobian(step: ReturnMap, x: np.ndarray, scale: float | np.ndarray, samples: int | None = None,
                        seed: int = 0) -> np.ndarray:
    """:func:`regression_fit`'s Jacobian, every pair required to succeed."""
    return regression_fit(step, x, scale, samples, seed).jacobian


def find_fixed_point(step: ReturnMap, x0: np.ndarray, iterations: int = 50, tol: float = 1e-10,
                     newton_steps: int = 0, delta: float | np.ndarray = 1e-6) -> tuple[np.ndarray, float]:
    """Fixed point of ``step`` from ``x0``: plain iteration x <- P(x) (converges to a
    stable cycle), then ``newton_steps`` Newton steps x <- x - (DP - I)^-1 (P(x) - x)
    (also finds unstable ones). Returns (x*, |P(x*) - x*|)."""
    x = np.asarray(x0, dtype=float)
    for _ in range(iterations):
        nxt = np.asarray(step(x))
        if np.linalg.norm(nxt - x) < tol:
            x = nxt
            break
        x = nxt
    for _ in range(newton_steps):
        residual = np.asarray(step(x)) - x
        if np.linalg.norm(residual) < tol:
            break
        jacobian = finite_difference_jacobian(step, x, delta)
        x = x - np.linalg.solve(jacobian - np.eye(len(x)), residual)
    return x, float(np.linalg.norm(np.asarray(step(x)) - x))


def analyse_return_map(step: ReturnMap, x0: np.ndarray, delta: float | np.ndarray = 1e-6,
                       iterations: int = 50, newton_steps: int = 0, tol: float = 1e-10,
                       regression_samples: int | None = None) -> PoincareAnalysis:
    """Find the fixed point near ``x0`` and linearise the map there: central differences
    with step ``delta``, or, with ``regression_samples``, :func:`regression_jacobian` with
    perturbation scale ``delta``."""
    x_star, residual = find_fixed_point(step, x0, iterations, tol, newton_steps, delta)
    if regression_samples:
        jacobian = regression_jacobian(step, x_star, delta, regression_samples)
    else:
        jacobian = finite_difference_jacobian(step, x_star, delta)
    return PoincareAnalysis(x_star, residual, jacobian)


def section_crossing(g_before: float, g_after: float, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """State where the section function g (g < 0 before the section, >= 0 after) crosses
    zero, linearly interpolated between two consecutive samples."""
    if not g_before < 0.0 <= g_after:
        raise ValueError(f"no crossing between g = {g_before} and g = {g_after}")
    w = -g_before / (g_after - g_before)
    return (1.0 - w) * np.asarray(before) + w * np.asarray(after)
