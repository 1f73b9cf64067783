"""Loading the RABBIT MuJoCo model (package data, found without working-directory paths).

Two variants:

* ``"paper"`` (default): the paper's model, ideal joints, torques limited to 150 N m.
* ``"drives"``: the real robot's drives. Each actuated joint gets the reflected rotor
  inertia of its 50:1 gear (armature = 3.32e-4 kg m^2 * 50^2 = 0.83 kg m^2) plus joint
  friction (Coulomb ``frictionloss`` and viscous ``damping``, see :class:`DriveParameters`).
  The actuator command stays the joint torque in N m (the gear is folded into it).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib.resources import as_file, files
from pathlib import Path

import mujoco

from rabbit_msgs_py.joints import ACTUATED_JOINTS, JOINT_NAMES  # noqa: F401  (re-exported)

MODEL_VARIANTS = ("paper", "drives")


@dataclass(frozen=True)
class DriveParameters:
    """RABBIT's drives (Chevallereau et al. 2003): gear ratio, rotor inertia (kg m^2),
    and joint friction. Friction figures are estimates for a harmonic-drive joint of this
    size (not identified on the robot): Coulomb 1.0 N m, viscous 0.5 N m s/rad."""

    gear_ratio: float = 50.0
    rotor_inertia: float = 3.32e-4
    coulomb_friction: float = 1.0
    viscous_friction: float = 0.5

    @property
    def armature(self) -> float:
        """Rotor inertia reflected to the joint, ``J_rotor * N^2`` (kg m^2)."""
        return self.rotor_inertia * self.gear_ratio**2


def model_path() -> Path:
    """Path of the packaged MJCF file."""
    with as_file(files("rabbit_sim") / "models" / "rabbit.xml") as path:
        return Path(path)


def load_model(variant: str = "paper", drives: DriveParameters | None = None) -> mujoco.MjModel:
    """Compile the RABBIT model. ``variant`` is one of :data:`MODEL_VARIANTS`."""
    if variant not in MODEL_VARIANTS:
        raise ValueError(f"unknown model variant {variant!r}; choose one of {MODEL_VARIANTS}")
    spec = mujoco.MjSpec.from_file(str(model_path()))
    if variant == "drives":
        params = drives or DriveParameters()
        for name in ACTUATED_JOINTS:
            joint = spec.joint(name)
            joint.armature = params.armature
            joint.frictionloss = params.coulomb_friction
            joint.damping = params.viscous_friction
    return spec.compile()
