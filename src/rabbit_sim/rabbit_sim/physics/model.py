"""Loading the RABBIT MuJoCo model (package data, found without working-directory paths),
with the model errors an experiment may ask for (:class:`ModelOptions`).

Two variants:

* ``"paper"`` (default): the paper's model, ideal joints, torques limited to 150 N m.
* ``"drives"``: the real robot's drives. Each actuated joint gets the reflected rotor
  inertia of its 50:1 gear (armature = 3.32e-4 kg m^2 * 50^2 = 0.83 kg m^2) plus joint
  friction (Coulomb ``frictionloss`` and viscous ``damping``, see :class:`DriveParameters`).
  The actuator command stays the joint torque in N m (the gear is folded into it).

On top of either variant: the foot-ground Coulomb friction coefficient (``friction``,
0.8 in the packaged model) and a scale on the torso's mass and rotational inertia
(``torso_mass_scale``; the torso is 12 kg of the robot's 32 kg).
"""

from __future__ import annotations

import functools

import math
from dataclasses import dataclass, field
from importlib.resources import as_file, files
from pathlib import Path

import mujoco

from rabbit_msgs_py.joints import ACTUATED_JOINTS, JOINT_NAMES  # noqa: F401  (re-exported)

MODEL_VARIANTS = ("paper", "drives")
FOOT_GEOMS = ("left_foot", "right_foot")


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


@dataclass(frozen=True)
class ModelOptions:
    """Which model an experiment runs on.

    variant: one of :data:`MODEL_VARIANTS`. drives: the drive figures of the ``drives``
    variant. friction: foot-ground sliding friction coefficient (None: the packaged 0.8).
    torso_mass_scale: factor on the torso's mass and inertia (1.0: the paper's 12 kg).
    """

    variant: str = "paper"
    friction: float | None = None
    torso_mass_scale: float = 1.0
    drives: DriveParameters = field(default_factory=DriveParameters)

    def __post_init__(self) -> None:
        if self.variant not in MODEL_VARIANTS:
            raise ValueError(f"unknown model variant {self.variant!r}; choose one of {MODEL_VARIANTS}")
        if self.friction is not None and not (math.isfinite(self.friction) and self.friction > 0.0):
            raise ValueError(f"friction must be a finite number > 0, got {self.friction}")
        if not (math.isfinite(self.torso_mass_scale) and self.torso_mass_scale > 0.0):
            raise ValueError(f"torso_mass_scale must be a finite number > 0, got {self.torso_mass_scale}")

    def to_dict(self) -> dict:
        """JSON-ready (what results and model cards record)."""
        return {"variant": self.variant, "friction": self.friction, "torso_mass_scale": self.torso_mass_scale}


def model_path() -> Path:
    """Path of the packaged MJCF scene (``models/scene.xml``: the floor, light and keyframe
    around the robot's own ``models/rabbit.xml``, as MuJoCo Menagerie lays out a model)."""
    with as_file(files("rabbit_sim") / "models" / "scene.xml") as path:
        return Path(path)


@functools.lru_cache(maxsize=1)
def model_sha256() -> str:
    """SHA-256 of the packaged model (``models/*.xml`` by name and content, in name order):
    the robot a controller spec was made for (its leg geometry and 1 ms tick are the model's).
    Read once per process (every spec build checks it)."""
    import hashlib

    digest = hashlib.sha256()
    for path in sorted(model_path().parent.glob("*.xml")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def load_model(options: ModelOptions | str = "paper", drives: DriveParameters | None = None) -> mujoco.MjModel:
    """Compile the RABBIT model for ``options`` (or a variant name, see :data:`MODEL_VARIANTS`)."""
    if isinstance(options, str):
        options = ModelOptions(variant=options, drives=drives or DriveParameters())
    spec = mujoco.MjSpec.from_file(str(model_path()))
    if options.variant == "drives":
        params = options.drives
        for name in ACTUATED_JOINTS:
            joint = spec.joint(name)
            joint.armature = params.armature
            joint.frictionloss = params.coulomb_friction
            joint.damping = params.viscous_friction
    if options.friction is not None:
        for name in FOOT_GEOMS:  # the feet have contact priority: their friction is the contact's
            spec.geom(name).friction[0] = options.friction
    if options.torso_mass_scale != 1.0:
        torso = spec.body("torso")
        torso.mass *= options.torso_mass_scale
        torso.inertia = [i * options.torso_mass_scale for i in torso.inertia]
    return spec.compile()
