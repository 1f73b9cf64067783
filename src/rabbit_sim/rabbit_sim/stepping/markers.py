"""RABBIT as 3D shapes for RViz and Foxglove (ROS-free core of ``/rabbit/markers``).

:class:`RobotShapes` reads the MJCF once — every robot geom's type, size and colour — and
turns a MuJoCo state into :class:`Shape` records in the world frame (``frame_id`` =
:data:`FRAME_ID`: MuJoCo's world, x forward along the walk, z up, origin on the floor at the
start; no TF is needed, set RViz's fixed frame to ``world``):

* torso, femurs and tibias: a cylinder per capsule (radius and length from the MJCF, axis
  along the capsule), coloured as the model's materials (left leg, right leg, torso);
* feet: a sphere each, drawn larger and in :data:`STANCE_RGBA` while the foot touches the
  ground (its touch sensor);
* the ground: a thin plate under the robot, following it along x;
* the push acting now: an arrow ending at the torso's centre of mass, :data:`PUSH_M_PER_N`
  long per newton; when no push acts, a ``delete`` shape removes it.

Shape ids are fixed, so each message replaces the previous one's shapes in a viewer.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

FRAME_ID = "world"
NAMESPACE = "rabbit"
STANCE_RGBA = (1.0, 0.85, 0.0, 1.0)
GROUND_RGBA = (0.55, 0.55, 0.55, 1.0)
PUSH_RGBA = (0.9, 0.1, 0.1, 1.0)
PUSH_M_PER_N = 0.004  # arrow length per newton of push (m/N): 100 N -> 0.4 m
GROUND_SIZE = (4.0, 1.0, 0.01)  # m
GROUND_ID, PUSH_ID = 100, 101

KINDS = ("cylinder", "sphere", "cube", "arrow", "delete")


@dataclass(frozen=True)
class Shape:
    """One shape in the world frame: ``position`` (m), ``orientation`` quaternion (w, x, y,
    z), ``scale`` (m: a cylinder's diameter x, diameter y, length; a sphere's diameter; a
    cube's sides; an arrow's shaft diameter, head diameter, head length), ``rgba`` 0-1,
    ``points`` (an arrow's start and end, m)."""

    id: int
    name: str
    kind: str
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    scale: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rgba: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    points: tuple[tuple[float, float, float], ...] = ()

    def axis(self) -> np.ndarray:
        """Unit vector of the shape's local z axis in the world frame (a cylinder's axis)."""
        w, x, y, z = self.orientation
        return np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])

    def ends(self) -> tuple[np.ndarray, np.ndarray]:
        """A cylinder's two end centres (m, world)."""
        half = 0.5 * self.scale[2] * self.axis()
        centre = np.asarray(self.position)
        return centre - half, centre + half


@dataclass(frozen=True)
class _Geom:
    id: int
    name: str
    kind: str
    scale: tuple[float, float, float]
    rgba: tuple[float, float, float, float]
    touch: int | None  # sensordata index of the foot's touch sensor


class RobotShapes:
    """The robot's geoms as shapes, for one MuJoCo model."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self._kinematics = mujoco.MjData(model)
        self._torso = model.body("torso").id
        self._geoms: list[_Geom] = []
        for g in range(model.ngeom):
            if model.geom_bodyid[g] == 0:  # the world's geoms (the floor): drawn as the ground plate
                continue
            name = model.geom(g).name
            size = model.geom_size[g]
            rgba = tuple(float(c) for c in (model.mat_rgba[model.geom_matid[g]] if model.geom_matid[g] >= 0
                                            else model.geom_rgba[g]))
            if model.geom_type[g] in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER):
                kind, scale = "cylinder", (2 * size[0], 2 * size[0], 2 * size[1])
            elif model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE:
                kind, scale = "sphere", (2 * size[0],) * 3
            elif model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
                kind, scale = "cube", tuple(2 * size)
            else:
                raise ValueError(f"geom {name!r}: no marker for MuJoCo geom type {model.geom_type[g]}")
            touch = None
            sensor = f"{name}_touch"
            if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, sensor) >= 0:
                touch = int(model.sensor_adr[model.sensor(sensor).id])
            self._geoms.append(_Geom(g, name, kind, tuple(float(s) for s in scale), rgba, touch))

    @property
    def names(self) -> list[str]:
        return [g.name for g in self._geoms]

    def shapes(self, data: mujoco.MjData) -> list[Shape]:
        """The robot, ground and push of ``data``: the positions of its ``qpos`` now (computed
        on a private copy: after ``mj_step`` the data's own ``geom_xpos`` still hold the
        step's start), the touch sensors and the torso's ``xfrc_applied``."""
        kin = self._kinematics
        kin.qpos[:] = data.qpos
        mujoco.mj_kinematics(self.model, kin)
        quat = np.empty(4)
        out = []
        for g in self._geoms:
            mujoco.mju_mat2Quat(quat, kin.geom_xmat[g.id])
            scale, rgba = g.scale, g.rgba
            if g.touch is not None and data.sensordata[g.touch] > 0.0:  # this foot is on the ground
                scale, rgba = tuple(1.6 * s for s in scale), STANCE_RGBA
            out.append(Shape(g.id, g.name, g.kind, tuple(float(p) for p in kin.geom_xpos[g.id]),
                             tuple(float(q) for q in quat), scale, rgba))
        x = float(kin.xpos[self._torso][0])
        out.append(Shape(GROUND_ID, "ground", "cube", (x, 0.0, -0.5 * GROUND_SIZE[2]), scale=GROUND_SIZE,
                         rgba=GROUND_RGBA))
        force = np.array(data.xfrc_applied[self._torso][:3])
        if np.any(force):
            end = np.array(kin.xipos[self._torso])
            start = end - PUSH_M_PER_N * force
            out.append(Shape(PUSH_ID, "push", "arrow", scale=(0.02, 0.045, 0.06), rgba=PUSH_RGBA,
                             points=(tuple(float(p) for p in start), tuple(float(p) for p in end))))
        else:
            out.append(Shape(PUSH_ID, "push", "delete"))
        return out


def marker_period_ticks(rate_hz: float, timestep: float) -> int:
    """Ticks between marker messages for ``rate_hz`` of sim time (0 = never)."""
    if rate_hz < 0.0 or not np.isfinite(rate_hz):
        raise ValueError(f"markers_rate must be a finite number >= 0 Hz, got {rate_hz}")
    return 0 if rate_hz == 0.0 else max(1, int(round(1.0 / (rate_hz * timestep))))
