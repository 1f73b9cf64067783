"""A URDF of RABBIT generated from the compiled MuJoCo model, for robot_state_publisher, RViz's
RobotModel and Foxglove's URDF layer.

:func:`urdf_from_model` writes the model's kinematic tree as URDF, read from the compiled
``MjModel`` (so a model variant's masses and drive friction come along):

* Links: one per MuJoCo body (``torso``, ``left_femur``, ``left_tibia``, ``right_femur``,
  ``right_tibia``) with its mass, centre of mass and principal inertia (kg, m, kg m^2), the
  root ``world`` (MuJoCo's world frame: x forward, z up, the floor at z = 0), and a frame per
  foot (``left_foot``, ``right_foot``: the foot sites, the contact points at the tibia tips).
* Joints, named as in ``/joint_states`` (:data:`rabbit_msgs_py.joints.JOINT_NAMES`): the planar
  base as ``x`` and ``z`` (prismatic, m; URDF needs limits: +-1e4 m) and ``torso_pitch``
  (continuous, rad) through the massless links ``base_x`` and ``base_z``; the hips and knees
  (revolute) with MuJoCo's axes and ranges (rad), the actuators' torque limits (N m) as effort
  limits, joint damping and dry friction as ``<dynamics>`` (zero in the paper model). MuJoCo
  has no joint velocity limit; URDF requires one: :data:`VELOCITY_LIMIT`.
* Geometry: each capsule as a cylinder (its radius and length, between the capsule's end
  centres), the foot spheres as spheres, in the model's colours; the foot spheres are also the
  collision geometry (the only geoms that touch the ground).

The packaged file ``share/rabbit_sim/urdf/rabbit.urdf`` (and ``rabbit_sim/urdf/rabbit.urdf``) is
this function's output for the paper model (``scripts/generate_urdf.py``; a test keeps it current).
``sim_node`` publishes the URDF of the model it simulates on ``robot_description``.
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import mujoco
import numpy as np

BASE_LIMIT = 1.0e4
"""Limit (m) of the planar base's prismatic joints (URDF requires one)."""
VELOCITY_LIMIT = 20.0
"""Joint velocity limit (rad/s, m/s for the base) written for every joint: not modelled in
MuJoCo, required by URDF."""
FOOT_SITES = ("left_foot", "right_foot")
PACKAGED_URDF = Path(__file__).resolve().parent / "urdf" / "rabbit.urdf"


def _numbers(values) -> str:
    return " ".join(f"{float(v):.9g}" for v in values) if len(values) else ""


def _origin(pos, quat=(1.0, 0.0, 0.0, 0.0)) -> str:
    """``<origin>`` of a MuJoCo position and (w, x, y, z) quaternion: URDF's fixed-axis roll,
    pitch, yaw (R = Rz Ry Rx)."""
    matrix = np.empty(9)
    mujoco.mju_quat2Mat(matrix, np.asarray(quat, dtype=float))
    r = matrix.reshape(3, 3)
    rpy = np.array([np.arctan2(r[2, 1], r[2, 2]), np.arctan2(-r[2, 0], np.hypot(r[2, 1], r[2, 2])),
                    np.arctan2(r[1, 0], r[0, 0])])
    rpy[np.abs(rpy) < 1e-12] = 0.0
    return f'<origin xyz="{_numbers(pos)}" rpy="{_numbers(rpy)}"/>'


def _geometry(model: mujoco.MjModel, g: int) -> str | None:
    size = model.geom_size[g]
    if model.geom_type[g] in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER):
        return f'<cylinder radius="{size[0]:.9g}" length="{2.0 * size[1]:.9g}"/>'
    if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE:
        return f'<sphere radius="{size[0]:.9g}"/>'
    return None  # no other shape on RABBIT


def _colour(model: mujoco.MjModel, g: int) -> str:
    """The geom's RGBA (its material's if it has one), 4 significant digits (MuJoCo keeps float32)."""
    material = model.geom_matid[g]
    rgba = model.mat_rgba[material] if material >= 0 else model.geom_rgba[g]
    return " ".join(f"{c:.4g}" for c in rgba)


def _link(model: mujoco.MjModel, body: int) -> list[str]:
    name = model.body(body).name
    lines = [f"  <link name={quoteattr(name)}>",
             "    <inertial>",
             f"      {_origin(model.body_ipos[body], model.body_iquat[body])}",
             f'      <mass value="{model.body_mass[body]:.9g}"/>',
             '      <inertia ixx="{:.9g}" ixy="0" ixz="0" iyy="{:.9g}" iyz="0" izz="{:.9g}"/>'.format(
                 *model.body_inertia[body]),
             "    </inertial>"]
    for g in np.flatnonzero(model.geom_bodyid == body):
        shape = _geometry(model, g)
        if shape is None:
            continue
        origin = _origin(model.geom_pos[g], model.geom_quat[g])
        geom = model.geom(g).name
        lines += [f"    <visual name={quoteattr(geom)}>", f"      {origin}", f"      <geometry>{shape}</geometry>",
                  f'      <material name={quoteattr(geom)}><color rgba="{_colour(model, g)}"/></material>',
                  "    </visual>"]
        if model.geom_contype[g] or model.geom_conaffinity[g]:
            lines += [f"    <collision name={quoteattr(geom)}>", f"      {origin}",
                      f"      <geometry>{shape}</geometry>", "    </collision>"]
    return lines + ["  </link>"]


def _joint(model: mujoco.MjModel, j: int, parent: str, child: str, origin: str) -> list[str]:
    name = model.joint(j).name
    kind = model.jnt_type[j]
    dof = model.jnt_dofadr[j]
    if kind == mujoco.mjtJoint.mjJNT_SLIDE:
        urdf_type, lower, upper, effort = "prismatic", -BASE_LIMIT, BASE_LIMIT, 0.0
    elif kind == mujoco.mjtJoint.mjJNT_HINGE:
        actuated = np.flatnonzero((model.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT)
                                  & (model.actuator_trnid[:, 0] == j))
        effort = float(np.max(np.abs(model.actuator_ctrlrange[actuated])) * model.actuator_gear[actuated[0], 0]) \
            if actuated.size else 0.0
        urdf_type = "revolute" if model.jnt_limited[j] else "continuous"
        lower, upper = model.jnt_range[j]
    else:
        raise ValueError(f"joint {name!r}: only slide and hinge joints have a URDF form here")
    if np.any(model.jnt_pos[j] != 0.0):
        raise ValueError(f"joint {name!r} is not at its body's origin; not supported")
    lines = [f"  <joint name={quoteattr(name)} type={quoteattr(urdf_type)}>", f"    {origin}",
             f"    <parent link={quoteattr(parent)}/>", f"    <child link={quoteattr(child)}/>",
             f'    <axis xyz="{_numbers(model.jnt_axis[j])}"/>']
    if urdf_type != "continuous":
        lines.append(f'    <limit lower="{lower:.9g}" upper="{upper:.9g}" effort="{effort:.9g}" '
                     f'velocity="{VELOCITY_LIMIT:g}"/>')
    else:
        lines.append(f'    <limit effort="{effort:.9g}" velocity="{VELOCITY_LIMIT:g}"/>')
    lines.append(f'    <dynamics damping="{model.dof_damping[dof]:.9g}" friction="{model.dof_frictionloss[dof]:.9g}"/>')
    return lines + ["  </joint>"]


def urdf_from_model(model: mujoco.MjModel, name: str = "rabbit") -> str:
    """The URDF (XML text) of ``model``'s robot; see the module docstring."""
    lines = ['<?xml version="1.0"?>',
             "<!-- Generated from the MuJoCo model by rabbit_sim.urdf (scripts/generate_urdf.py): do not edit. -->",
             f"<robot name={quoteattr(name)}>", '  <link name="world"/>']
    for body in range(1, model.nbody):
        parent_body = model.body_parentid[body]
        parent = "world" if parent_body == 0 else model.body(parent_body).name
        child = model.body(body).name
        joints = list(range(model.body_jntadr[body], model.body_jntadr[body] + model.body_jntnum[body]))
        origin = _origin(model.body_pos[body], model.body_quat[body])
        if not joints:
            lines += [f"  <joint name={quoteattr(child + '_fixed')} type=\"fixed\">", f"    {origin}",
                      f"    <parent link={quoteattr(parent)}/>", f"    <child link={quoteattr(child)}/>", "  </joint>"]
        for k, j in enumerate(joints):  # a chain through massless links for a body with several joints
            last = k == len(joints) - 1
            link = child if last else f"base_{model.joint(j).name}"
            if not last:
                lines.append(f"  <link name={quoteattr(link)}/>")
            lines += _joint(model, j, parent, link, origin if k == 0 else _origin((0.0, 0.0, 0.0)))
            parent = link
        lines += _link(model, body)
    for site in FOOT_SITES:
        s = model.site(site).id
        lines += [f"  <link name={quoteattr(site)}/>",
                  f"  <joint name={quoteattr(site + '_fixed')} type=\"fixed\">",
                  f"    {_origin(model.site_pos[s], model.site_quat[s])}",
                  f"    <parent link={quoteattr(model.body(model.site_bodyid[s]).name)}/>",
                  f"    <child link={quoteattr(site)}/>", "  </joint>"]
    return "\n".join(lines + ["</robot>"]) + "\n"


def packaged_urdf() -> str:
    """The packaged URDF (the paper model's)."""
    return PACKAGED_URDF.read_text()
