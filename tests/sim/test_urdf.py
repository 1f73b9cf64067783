"""The URDF generated from the MuJoCo model (``rabbit_sim.urdf``): the packaged file is current,
and every mass, centre of mass, inertia, joint axis, limit and drive figure is MuJoCo's."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yourdfpy

from rabbit_msgs_py.joints import JOINT_NAMES
from rabbit_sim.physics.model import ModelOptions, load_model
from rabbit_sim.urdf import PACKAGED_URDF, packaged_urdf, urdf_from_model

pytestmark = pytest.mark.sim

ROOT = Path(__file__).resolve().parents[2]


def _parse(text: str) -> yourdfpy.URDF:
    return yourdfpy.URDF.load(io.StringIO(text), load_meshes=False)


def test_the_packaged_urdf_is_the_paper_models_and_installed_with_the_package():
    assert packaged_urdf() == urdf_from_model(load_model("paper"))
    out = subprocess.run([sys.executable, "scripts/generate_urdf.py", "--check"], cwd=ROOT, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    setup = (ROOT / "src/rabbit_sim/setup.py").read_text()
    assert '"share/" + PACKAGE + "/urdf"' in setup and PACKAGED_URDF.name in setup


def test_an_out_of_date_urdf_is_reported(tmp_path):
    stale = tmp_path / "rabbit.urdf"
    stale.write_text(packaged_urdf().replace('value="12"', 'value="13"'))
    out = subprocess.run([sys.executable, "scripts/generate_urdf.py", "--check", "--out", str(stale)], cwd=ROOT,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 1 and "out of date" in out.stderr


@pytest.mark.parametrize("options", [ModelOptions("paper"), ModelOptions("drives", torso_mass_scale=1.15)])
def test_links_and_joints_carry_mujocos_masses_inertias_axes_limits_and_drives(options):
    model = load_model(options)
    robot = _parse(urdf_from_model(model))
    assert robot.validate()
    assert list(robot.actuated_joint_names) == list(JOINT_NAMES)  # the planar base as x / z / pitch, in order
    total = 0.0
    for body in ("torso", "left_femur", "left_tibia", "right_femur", "right_tibia"):
        b = model.body(body).id
        inertial = robot.link_map[body].inertial
        assert inertial.mass == pytest.approx(model.body_mass[b], rel=1e-8)
        assert np.allclose(inertial.origin[:3, 3], model.body_ipos[b])
        assert np.allclose(np.diag(inertial.inertia), model.body_inertia[b], rtol=1e-8)
        total += inertial.mass
    assert total == pytest.approx(sum(model.body_mass), rel=1e-8)
    for name in JOINT_NAMES:
        j, joint = model.joint(name).id, robot.joint_map[name]
        assert np.allclose(joint.axis, model.jnt_axis[j])
        dof = model.jnt_dofadr[j]
        assert float(joint.dynamics.damping) == pytest.approx(model.dof_damping[dof])
        assert float(joint.dynamics.friction) == pytest.approx(model.dof_frictionloss[dof])
        if name in JOINT_NAMES[3:]:
            assert joint.type == "revolute"
            assert (joint.limit.lower, joint.limit.upper) == pytest.approx(tuple(model.jnt_range[j]))
            assert joint.limit.effort == pytest.approx(150.0)
    assert [robot.joint_map[n].type for n in JOINT_NAMES[:3]] == ["prismatic", "prismatic", "continuous"]
    if options.variant == "drives":
        assert float(robot.joint_map["left_knee"].dynamics.damping) > 0.0
