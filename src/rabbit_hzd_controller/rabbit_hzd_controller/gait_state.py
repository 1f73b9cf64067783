"""Robot states that lie on a gait's zero-dynamics surface, to start a walk from.

Used to start simulations (scripts, tests, the Gymnasium environment, the gait
optimizer) in a posture and velocity consistent with a gait instead of from standing.
"""

from __future__ import annotations

from math import cos
from typing import Sequence

from .alpha import alpha_matrix
from .bezier import bezier, bezier_derivative
from .controller import Leg
from .kinematics import LegGeometry, foot_from_hip, foot_velocity_from_hip
from .phase import phase_bounds_from_alpha, stance_hip_position


def pitch_for_phase(
    alpha: Sequence[float], tau: float, geometry: LegGeometry, pitch_guess: float = 0.0
) -> float:
    """Torso pitch (rad) at which the stance-leg outputs ``y_d(tau)`` put the hip at the
    phase ``tau`` (Newton's method on ``p_hip(pitch) = p_plus + tau * span``)."""
    m = alpha_matrix(alpha)
    bounds = phase_bounds_from_alpha(alpha, geometry)
    hip, knee = bezier(m[:, 0], tau), bezier(m[:, 1], tau)
    target = bounds.p_plus + tau * bounds.span
    pitch = pitch_guess
    for _ in range(50):
        phi_f, phi_t = hip - pitch, hip - pitch - knee
        residual = stance_hip_position(geometry, pitch, hip, knee) - target
        slope = geometry.femur * cos(phi_f) + geometry.tibia * cos(phi_t)  # d p_hip / d pitch
        step = residual / slope
        pitch -= step
        if abs(step) < 1e-13:
            break
    return pitch


def state_on_gait(
    alpha: Sequence[float],
    speed: float,
    geometry: LegGeometry | None = None,
    tau: float = 0.0,
    stance: Leg = Leg.LEFT,
    stance_foot_x: float = 0.0,
) -> tuple[list[float], list[float]]:
    """Joint positions and velocities (``JOINT_NAMES`` order) on the gait at phase ``tau``.

    The stance foot is on the ground (z = 0) at ``stance_foot_x``, the actuated joints sit
    on their desired outputs and move along them with the hip advancing at ``speed`` m/s
    (``dtau/dt = speed / step length``); the torso pitch rate follows from the pinned
    stance foot.
    """
    geometry = geometry or LegGeometry()
    m = alpha_matrix(alpha)
    bounds = phase_bounds_from_alpha(alpha, geometry)
    pitch = pitch_for_phase(alpha, tau, geometry, pitch_guess=0.0)
    y = [bezier(m[:, j], tau) for j in range(4)]
    dtau = speed / bounds.span
    dy = [bezier_derivative(m[:, j], tau) * dtau for j in range(4)]
    sh, sk = y[0], y[1]
    dsh, dsk = dy[0], dy[1]
    phi_f, phi_t = sh - pitch, sh - pitch - sk
    # p_hip = -(lf sin phi_f + lt sin phi_t); solve d p_hip/dt = speed for the pitch rate.
    a = geometry.femur * cos(phi_f) + geometry.tibia * cos(phi_t)
    dpitch = dsh - (geometry.tibia * cos(phi_t) * dsk - speed) / a
    fx, fz = foot_from_hip(geometry, pitch, sh, sk)
    dfx, dfz = foot_velocity_from_hip(geometry, pitch, sh, sk, dpitch, dsh, dsk)
    x_hip, z_hip = stance_foot_x - fx, -fz
    if stance is Leg.LEFT:
        joints, rates = [y[0], y[1], y[2], y[3]], [dy[0], dy[1], dy[2], dy[3]]
    else:
        joints, rates = [y[2], y[3], y[0], y[1]], [dy[2], dy[3], dy[0], dy[1]]
    qpos = [x_hip, z_hip, pitch, *joints]
    qvel = [-dfx, -dfz, dpitch, *rates]
    return qpos, qvel


