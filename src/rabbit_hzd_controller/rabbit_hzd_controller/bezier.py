"""Degree-M Bezier polynomials, the desired outputs of the HZD virtual constraints.

``y_d(tau) = sum_k a[k] * C(M, k) * tau**k * (1 - tau)**(M - k)`` for ``tau`` in [0, 1].

Identities used throughout (and tested): ``y_d(0) = a[0]``, ``y_d(1) = a[M]``,
``dy_d/dtau(0) = M (a[1] - a[0])`` and ``dy_d/dtau(1) = M (a[M] - a[M-1])``.

The functions here are pure and work on plain Python floats (the states on a gait, gait
design and tests); the 1 kHz tick evaluates the same polynomials compiled, in
:mod:`.law`. ``bezier_matrix`` is the vectorised form for plotting, fitting and tests.
"""

from __future__ import annotations

from math import comb
from typing import Sequence

import numpy as np

DEGREE = 5
"""Degree of the HZD output polynomials (the paper's M = 5): 6 coefficients."""


def bernstein(tau: float, degree: int = DEGREE) -> list[float]:
    """Bernstein basis ``b_k(tau) = C(M,k) tau^k (1-tau)^(M-k)``, k = 0..M."""
    s = 1.0 - tau
    tpow = [1.0] * (degree + 1)
    spow = [1.0] * (degree + 1)
    for k in range(1, degree + 1):
        tpow[k] = tpow[k - 1] * tau
        spow[k] = spow[k - 1] * s
    return [comb(degree, k) * tpow[k] * spow[degree - k] for k in range(degree + 1)]


def bezier(coeffs: Sequence[float], tau: float) -> float:
    """Value of the Bezier polynomial with ``coeffs`` (length M+1) at ``tau``."""
    basis = bernstein(tau, len(coeffs) - 1)
    return sum(c * b for c, b in zip(coeffs, basis))


def bezier_derivative(coeffs: Sequence[float], tau: float) -> float:
    """``d y_d / d tau`` at ``tau``: a degree M-1 Bezier of ``M (a[k+1] - a[k])``."""
    degree = len(coeffs) - 1
    diffs = [degree * (coeffs[k + 1] - coeffs[k]) for k in range(degree)]
    return bezier(diffs, tau)


def bezier_matrix(taus: np.ndarray, degree: int = DEGREE) -> np.ndarray:
    """Basis matrix ``B[i, k] = b_k(taus[i])`` so that ``B @ coeffs`` samples the curve."""
    taus = np.asarray(taus, dtype=float)[:, None]
    k = np.arange(degree + 1)[None, :]
    binom = np.array([comb(degree, int(i)) for i in range(degree + 1)], dtype=float)[None, :]
    return binom * taus**k * (1.0 - taus) ** (degree - k)
