"""A kinematic first guess for a gait: inverse kinematics of a simple walking pattern,
fitted with Bezier polynomials. It seeds the gait optimizer; it is not itself optimal.

Pattern (stance foot at the origin, world axes): the hip moves from ``-L/2`` to ``+L/2``
at a constant height ``h`` with a constant torso pitch; the swing foot travels from
``-L`` to ``+L`` along a smooth profile, lifted by ``clearance`` at mid-step.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import pi, sin

import numpy as np

from rabbit_hzd_controller.alpha import N_FREE, SWAP_LEGS, expand_alpha
from rabbit_hzd_controller.bezier import bezier_matrix
from rabbit_hzd_controller.kinematics import LegGeometry, leg_inverse_kinematics


@dataclass(frozen=True)
class SeedPattern:
    """Walking pattern parameters: lengths in m, angles in rad."""

    step_length: float = 0.45
    hip_height: float = 0.75
    torso_pitch: float = 0.05
    clearance: float = 0.05
    hip_dip: float = 0.0


def seed_joint_angles(pattern: SeedPattern, taus: np.ndarray, geometry: LegGeometry) -> np.ndarray:
    """Relative joint angles (stance hip, stance knee, swing hip, swing knee) at ``taus``."""
    L = pattern.step_length
    out = np.zeros((len(taus), 4))
    for i, tau in enumerate(taus):
        p = -L / 2 + L * tau
        h = pattern.hip_height - pattern.hip_dip * sin(pi * tau)
        smooth = tau - sin(2 * pi * tau) / (2 * pi)  # 0 -> 1 with zero end slopes
        swing_x = -L + 2 * L * smooth
        swing_z = pattern.clearance * sin(pi * tau)
        for col, (fx, fz) in enumerate(((-p, -h), (swing_x - p, swing_z - h))):
            phi_f, phi_t = leg_inverse_kinematics(geometry, fx, fz)
            out[i, 2 * col] = phi_f + pattern.torso_pitch
            out[i, 2 * col + 1] = phi_f - phi_t
    return out


def seed_free_alpha(pattern: SeedPattern, geometry: LegGeometry | None = None) -> np.ndarray:
    """Least-squares Bezier fit of :func:`seed_joint_angles` with exact end points,
    returned as the 20 free coefficients (impact equalities hold by construction)."""
    geometry = geometry or LegGeometry()
    taus = np.linspace(0.0, 1.0, 41)
    angles = seed_joint_angles(pattern, taus, geometry)
    basis = bezier_matrix(taus)
    coeffs = np.zeros((6, 4))
    for j in range(4):
        first, last = angles[0, j], angles[-1, j]
        rhs = angles[:, j] - basis[:, 0] * first - basis[:, 5] * last
        inner, *_ = np.linalg.lstsq(basis[:, 1:5], rhs, rcond=None)
        coeffs[:, j] = [first, *inner, last]
    # Symmetrise the end rows exactly (the pattern is symmetric up to round-off).
    start = 0.5 * (coeffs[0] + coeffs[5][list(SWAP_LEGS)])
    free = coeffs[:5].reshape(-1).copy()
    free[:4] = start
    assert free.size == N_FREE
    expand_alpha(free)
    return free
