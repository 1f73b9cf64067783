"""What the HZD phase variable tau(q) is built from: the stance hip position and the phase
bounds a gait implies.

``tau = (p_hip - p_plus) / (p_minus - p_plus)``, saturated to [0, 1], where ``p_hip`` is the
horizontal position of the hip relative to the stance foot (m, world x axis) and
``p_plus`` / ``p_minus`` are its values at the start / end of a step. ``p_hip`` depends on
the torso pitch and the stance-leg angles only, so tau is state based (no clock). tau
and its rate are computed in one place, the controller's tick
(:meth:`rabbit_hzd_controller.controller.HZDController.compute`), which the tests check
against the law written out from the paper.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from . import law
from .alpha import alpha_matrix
from .kinematics import LegGeometry, foot_from_hip


@dataclass(frozen=True)
class PhaseBounds:
    """Hip position relative to the stance foot at the start (``p_plus``) and end
    (``p_minus``) of a step, in m. ``p_minus > p_plus`` for forward walking."""

    p_plus: float
    p_minus: float

    def __post_init__(self) -> None:
        if not self.p_minus > self.p_plus:
            raise ValueError(
                f"phase bounds need p_minus > p_plus, got p_plus={self.p_plus}, p_minus={self.p_minus}"
            )

    @property
    def span(self) -> float:
        """``p_minus - p_plus`` (m): the hip travel over one step, i.e. the step length."""
        return self.p_minus - self.p_plus


def stance_hip_position(geom: LegGeometry, pitch: float, hip: float, knee: float) -> float:
    """Horizontal hip position relative to the stance foot, ``p_hip(q)`` (m)."""
    return -foot_from_hip(geom, pitch, hip, knee)[0]


NO_STEP = "end-of-step posture has both feet at the same point: no step"


def end_of_step_pitch(alpha: Sequence[float], geom: LegGeometry) -> float:
    """Torso pitch (rad) at which the end-of-step posture ``alpha[5]`` has both feet at the
    same height with the swing foot ahead: the touchdown posture of the gait (compiled:
    :func:`.law.end_of_step_pitch`, the controller's entry check runs the same)."""
    pitch = law.end_of_step_pitch(_flat(alpha), geom.femur, geom.tibia)
    if pitch != pitch:
        raise ValueError(NO_STEP)
    return float(pitch)


def phase_bounds_from_alpha(alpha: Sequence[float], geom: LegGeometry) -> PhaseBounds:
    """``p_plus`` and ``p_minus`` implied by a gait's Bezier coefficients.

    At the end of a step (tau = 1) the joints sit at ``alpha[5]`` and both feet are on the
    ground; that fixes the torso pitch (:func:`end_of_step_pitch`), hence ``p_minus`` (hip
    relative to the stance foot) and the step length ``L`` (foot to foot). Positions are
    continuous through impact and the legs swap roles, so the next step starts at
    ``p_plus = p_minus - L`` (compiled: :func:`.law.phase_bounds`).
    """
    p_plus, p_minus = law.phase_bounds(_flat(alpha), geom.femur, geom.tibia)
    if p_plus != p_plus:
        raise ValueError(NO_STEP)
    return PhaseBounds(p_plus=float(p_plus), p_minus=float(p_minus))


def _flat(alpha: Sequence[float]) -> np.ndarray:
    """A gait's 24 coefficients as a contiguous float vector (raises for another size)."""
    return np.ascontiguousarray(alpha_matrix(alpha)).reshape(-1)
