"""Planar leg kinematics of RABBIT, in the world frame (x forward, z up), in metres.

Angles follow the model (``rabbit_sim/models/rabbit.xml``): torso pitch ``q_t`` from
vertical, + leaning forward; hip ``q_h`` femur relative to torso, + flexion; knee ``q_k``
tibia relative to femur, + flexion. The absolute link angles from the downward vertical
(+ = pointing forward) are then ``phi_f = q_h - q_t`` (femur) and ``phi_t = phi_f - q_k``
(tibia).

These are the only kinematics the HZD controller needs: the phase variable is the
horizontal hip position relative to the stance foot and touchdown is the swing foot
reaching the ground, both functions of joint angles (and hip height) alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import acos, atan2, cos, hypot, sin

from numba import njit


@dataclass(frozen=True)
class LegGeometry:
    """Link lengths of one leg (m), hip joint to knee joint to point foot."""

    femur: float = 0.4
    tibia: float = 0.4

    @property
    def length(self) -> float:
        """Straight-leg length, hip to foot (m)."""
        return self.femur + self.tibia


@njit(cache=True)
def foot_position(femur: float, tibia: float, pitch: float, hip: float, knee: float) -> tuple[float, float]:
    """Foot position relative to the hip joint, world axes (m), of a leg with links ``femur``
    and ``tibia`` (m) at torso pitch, hip and knee angles (rad). Compiled: the law's gait
    checks call it too (:mod:`.law`)."""
    phi_f = hip - pitch
    phi_t = phi_f - knee
    return femur * sin(phi_f) + tibia * sin(phi_t), -(femur * cos(phi_f) + tibia * cos(phi_t))


def foot_from_hip(geom: LegGeometry, pitch: float, hip: float, knee: float) -> tuple[float, float]:
    """Foot position relative to the hip joint, world axes (m): :func:`foot_position`."""
    return foot_position(geom.femur, geom.tibia, pitch, hip, knee)


def foot_velocity_from_hip(
    geom: LegGeometry,
    pitch: float,
    hip: float,
    knee: float,
    dpitch: float,
    dhip: float,
    dknee: float,
) -> tuple[float, float]:
    """Time derivative of :func:`foot_from_hip` (m/s), by the chain rule."""
    phi_f = hip - pitch
    phi_t = phi_f - knee
    dphi_f = dhip - dpitch
    dphi_t = dphi_f - dknee
    return (
        geom.femur * cos(phi_f) * dphi_f + geom.tibia * cos(phi_t) * dphi_t,
        geom.femur * sin(phi_f) * dphi_f + geom.tibia * sin(phi_t) * dphi_t,
    )


def leg_inverse_kinematics(geom: LegGeometry, x: float, z: float) -> tuple[float, float]:
    """Absolute link angles ``(phi_f, phi_t)`` (rad) that put the foot at ``(x, z)``
    relative to the hip, knee bent forward (``q_k = phi_f - phi_t >= 0``).

    Raises ``ValueError`` when the point is out of reach.
    """
    lf, lt = geom.femur, geom.tibia
    d = hypot(x, z)
    if d > lf + lt + 1e-12 or d < abs(lf - lt) - 1e-12:
        raise ValueError(f"foot position ({x:.3f}, {z:.3f}) m is out of the leg's reach")
    d = min(max(d, abs(lf - lt)), lf + lt)
    # Direction of the hip->foot line from the downward vertical, + forward.
    line = atan2(x, -z)
    # Interior angle at the hip between the femur and the hip->foot line.
    cos_hip = (lf * lf + d * d - lt * lt) / (2.0 * lf * d) if d > 0 else 1.0
    offset = acos(min(1.0, max(-1.0, cos_hip)))
    phi_f = line + offset
    kx, kz = lf * sin(phi_f), -lf * cos(phi_f)
    phi_t = atan2(x - kx, -(z - kz))
    return phi_f, phi_t
