"""Phase variable, its chain-rule rate, phase bounds from alpha, and leg kinematics."""

from math import cos

import numpy as np
import pytest

from rabbit_hzd_controller.alpha import alpha_matrix
from rabbit_hzd_controller.kinematics import (
    LegGeometry,
    foot_from_hip,
    foot_velocity_from_hip,
    leg_inverse_kinematics,
)
from rabbit_hzd_controller.phase import (
    PhaseBounds,
    end_of_step_pitch,
    phase_bounds_from_alpha,
    stance_hip_position,
)
from rabbit_policy.runtime.gait_library import GaitLibrary

pytestmark = pytest.mark.unit

GEOM = LegGeometry()


def test_bounds_must_be_ordered():
    with pytest.raises(ValueError):
        PhaseBounds(p_plus=0.2, p_minus=-0.2)


def test_foot_velocity_is_the_time_derivative():
    rng = np.random.default_rng(1)
    h = 1e-6
    for _ in range(20):
        q = rng.uniform([-0.4, -1, 0], [0.4, 1, 1.5])
        dq = rng.normal(size=3)
        vx, vz = foot_velocity_from_hip(GEOM, *q, *dq)
        xp, zp = foot_from_hip(GEOM, *(q + h * dq))
        xm, zm = foot_from_hip(GEOM, *(q - h * dq))
        assert vx == pytest.approx((xp - xm) / (2 * h), abs=1e-7)
        assert vz == pytest.approx((zp - zm) / (2 * h), abs=1e-7)


def test_inverse_kinematics_round_trip():
    for x, z in [(0.1, -0.75), (-0.2, -0.7), (0.0, -0.5), (0.3, -0.6)]:
        phi_f, phi_t = leg_inverse_kinematics(GEOM, x, z)
        assert phi_f - phi_t >= 0.0  # knee bends forward
        # foot_from_hip with pitch 0: hip = phi_f, knee = phi_f - phi_t
        fx, fz = foot_from_hip(GEOM, 0.0, phi_f, phi_f - phi_t)
        assert (fx, fz) == pytest.approx((x, z), abs=1e-12)
    with pytest.raises(ValueError):
        leg_inverse_kinematics(GEOM, 0.5, -0.8)


@pytest.fixture(scope="module")
def library():
    return GaitLibrary.load()


def test_bounds_from_alpha_put_both_feet_down_at_the_end(library):
    for gait in library.gaits:
        end = alpha_matrix(gait.alpha)[-1]
        pitch = end_of_step_pitch(gait.alpha, GEOM)
        st = foot_from_hip(GEOM, pitch, end[0], end[1])
        sw = foot_from_hip(GEOM, pitch, end[2], end[3])
        assert st[1] == pytest.approx(sw[1], abs=1e-12)  # same height
        assert sw[0] > st[0]  # swing foot ahead
        b = phase_bounds_from_alpha(gait.alpha, GEOM)
        assert b.p_minus == pytest.approx(-st[0])
        assert b.span == pytest.approx(sw[0] - st[0])
        # The start posture (alpha[0] = relabelled alpha[5]) is at p_plus.
        start = alpha_matrix(gait.alpha)[0]
        assert stance_hip_position(GEOM, pitch, start[0], start[1]) == pytest.approx(b.p_plus)


def test_stance_hip_position_rate_by_chain_rule():
    """d p_hip / dt as the controller computes it equals the finite difference."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        pitch, hip, knee = rng.uniform([-0.3, -0.6, 0.1], [0.3, 0.6, 1.0])
        dpitch, dhip, dknee = rng.normal(size=3)
        phi_f, phi_t = hip - pitch, hip - pitch - knee
        rate = -(GEOM.femur * cos(phi_f) * (dhip - dpitch) + GEOM.tibia * cos(phi_t) * (dhip - dpitch - dknee))
        h = 1e-6
        fd = (stance_hip_position(GEOM, pitch + h * dpitch, hip + h * dhip, knee + h * dknee)
              - stance_hip_position(GEOM, pitch - h * dpitch, hip - h * dhip, knee - h * dknee)) / (2 * h)
        assert rate == pytest.approx(fd, abs=1e-7)
