"""The Bezier coefficient set alpha and the paper's impact equalities.

alpha holds 6 coefficients for each of the 4 actuated outputs, in stance/swing order
``OUTPUTS = (stance hip, stance knee, swing hip, swing knee)`` (relative joint angles,
rad). As a matrix it is 6 x 4 (row k = coefficient k, column j = output j); flattened
*coefficient-major* it is the paper's 24-vector: ``flat[4 k + j] = alpha[k, j]``.

The paper makes the outputs at the start of a step equal the relabelled outputs at the
end of the previous one (1-based): alpha[1]=alpha[23], alpha[2]=alpha[24],
alpha[3]=alpha[21], alpha[4]=alpha[22]. In 0-based matrix terms the last row is a
permutation of the first: ``alpha[5] = (alpha[0,2], alpha[0,3], alpha[0,0], alpha[0,1])``.
The 20 free numbers are therefore rows 0..4, flattened the same way.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

OUTPUTS = ("stance_hip", "stance_knee", "swing_hip", "swing_knee")
N_OUTPUTS = 4
N_COEFFS = 6
N_ALPHA = N_OUTPUTS * N_COEFFS  # 24
N_FREE = N_ALPHA - N_OUTPUTS  # 20

SWAP_LEGS = (2, 3, 0, 1)
"""Output permutation that relabels stance <-> swing."""
_SWAP_INDEX = np.array(SWAP_LEGS)


def expand_alpha(free: Sequence[float]) -> np.ndarray:
    """20 free coefficients -> the full 24-vector satisfying the impact equalities."""
    free = np.asarray(free, dtype=float).reshape(-1)
    if free.shape != (N_FREE,):
        raise ValueError(f"expected {N_FREE} free Bezier coefficients, got {free.size}")
    return np.concatenate([free, free[_SWAP_INDEX]])


def reduce_alpha(alpha: Sequence[float], atol: float = 1e-9) -> np.ndarray:
    """Inverse of :func:`expand_alpha`: the 20 free numbers of a consistent 24-vector.

    Raises ``ValueError`` if ``alpha`` violates the impact equalities by more than ``atol``.
    """
    alpha = np.asarray(alpha, dtype=float).reshape(-1)
    if alpha.shape != (N_ALPHA,):
        raise ValueError(f"expected {N_ALPHA} Bezier coefficients, got {alpha.size}")
    free = alpha[:N_FREE]
    err = np.max(np.abs(alpha[N_FREE:] - free[list(SWAP_LEGS)]))
    if err > atol:
        raise ValueError(f"alpha violates the impact equalities by {err:.3g} rad")
    return free.copy()


def alpha_matrix(alpha: Sequence[float]) -> np.ndarray:
    """24-vector -> 6 x 4 matrix (row = coefficient, column = output)."""
    alpha = np.asarray(alpha, dtype=float).reshape(-1)
    if alpha.shape != (N_ALPHA,):
        raise ValueError(f"expected {N_ALPHA} Bezier coefficients, got {alpha.size}")
    return alpha.reshape(N_COEFFS, N_OUTPUTS)


def alpha_vector(matrix: np.ndarray) -> np.ndarray:
    """6 x 4 matrix -> coefficient-major 24-vector."""
    matrix = np.asarray(matrix, dtype=float)
    if matrix.shape != (N_COEFFS, N_OUTPUTS):
        raise ValueError(f"expected a {N_COEFFS}x{N_OUTPUTS} matrix, got {matrix.shape}")
    return matrix.reshape(-1).copy()


def impact_violation(alpha: Sequence[float]) -> float:
    """Largest violation (rad) of the impact equalities by a 24-vector."""
    m = alpha_matrix(alpha)
    return float(np.max(np.abs(m[-1] - m[0, list(SWAP_LEGS)])))
