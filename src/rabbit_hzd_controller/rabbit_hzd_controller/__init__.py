"""ROS-free HZD control core for RABBIT: Bezier virtual constraints, phase, PD tracking,
stance switching, and the gait description. The ROS node lives in :mod:`.hzd_controller_node`."""

from .alpha import N_ALPHA, N_FREE, OUTPUTS, alpha_matrix, expand_alpha, reduce_alpha
from .bezier import DEGREE, bezier, bezier_derivative, bezier_matrix, bernstein
from .controller import (
    ACTUATED_JOINTS,
    JOINT_NAMES,
    ControllerConfig,
    HZDController,
    Leg,
    infer_stance,
    validate_alpha,
    validate_kd,
)
from .gait import Gait
from .kinematics import LegGeometry, foot_from_hip, foot_velocity_from_hip, leg_inverse_kinematics
from .phase import PhaseBounds, phase_bounds_from_alpha, stance_hip_position

__all__ = [
    "ACTUATED_JOINTS", "DEGREE", "JOINT_NAMES", "N_ALPHA", "N_FREE", "OUTPUTS",
    "ControllerConfig", "Gait", "HZDController", "Leg", "LegGeometry", "PhaseBounds",
    "alpha_matrix", "bernstein", "bezier", "bezier_derivative", "bezier_matrix",
    "expand_alpha", "foot_from_hip", "foot_velocity_from_hip", "infer_stance", "leg_inverse_kinematics",
    "phase_bounds_from_alpha", "reduce_alpha", "stance_hip_position",
    "validate_alpha", "validate_kd",
]
