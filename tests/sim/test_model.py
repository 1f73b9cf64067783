"""The compiled MuJoCo model against the paper's Table I and the issue's figures."""

import mujoco
import numpy as np
import pytest

from rabbit_hzd_controller.kinematics import LegGeometry, foot_from_hip
from rabbit_msgs_py.joints import ACTUATED_JOINTS, JOINT_NAMES
from rabbit_sim.physics.model import DriveParameters, load_model, model_path

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def model():
    return load_model()


def test_model_file_is_package_data_a_scene_around_the_robot():
    """Menagerie's layout: scene.xml (floor, light, keyframe) includes the robot's rabbit.xml,
    which has none of them and no sensor nothing reads."""
    assert model_path().is_file() and model_path().name == "scene.xml"
    robot = (model_path().parent / "rabbit.xml").read_text()
    assert '<include file="rabbit.xml"/>' in model_path().read_text()
    for scene_only in ('name="floor"', "<light", "<keyframe", "<visual"):
        assert scene_only not in robot
    model = load_model()
    assert [model.sensor(i).name for i in range(model.nsensor)] == ["left_foot_touch", "right_foot_touch"]


def test_timestep_is_one_millisecond(model):
    assert model.opt.timestep == pytest.approx(0.001)


def test_joint_order_and_types(model):
    names = [model.joint(i).name for i in range(model.njnt)]
    assert tuple(names) == JOINT_NAMES
    assert model.nq == model.nv == 7
    types = [int(model.jnt_type[i]) for i in range(model.njnt)]
    slide, hinge = int(mujoco.mjtJoint.mjJNT_SLIDE), int(mujoco.mjtJoint.mjJNT_HINGE)
    assert types == [slide, slide, hinge, hinge, hinge, hinge, hinge]
    np.testing.assert_allclose(model.jnt_axis[0], [1, 0, 0])
    np.testing.assert_allclose(model.jnt_axis[1], [0, 0, 1])
    for i in range(2, 7):  # every hinge turns about the y axis: the model is planar
        assert abs(model.jnt_axis[i][1]) == pytest.approx(1.0)


@pytest.mark.parametrize(
    "body, mass, inertia, com_z",
    [
        ("torso", 12.0, 1.33, 0.24),
        ("left_femur", 6.8, 0.47, -0.11),
        ("right_femur", 6.8, 0.47, -0.11),
        ("left_tibia", 3.2, 0.20, -0.24),
        ("right_tibia", 3.2, 0.20, -0.24),
    ],
)
def test_table_one(model, body, mass, inertia, com_z):
    b = model.body(body)
    assert b.mass[0] == pytest.approx(mass)
    # Inertia about the CoM, about the y axis (the planar rotation axis); the body's
    # principal frame is aligned with its local frame.
    np.testing.assert_allclose(b.iquat, [1, 0, 0, 0], atol=1e-12)
    assert b.inertia[1] == pytest.approx(inertia)
    assert b.ipos[2] == pytest.approx(com_z)
    assert b.ipos[0] == pytest.approx(0.0)


def test_total_mass(model):
    assert sum(model.body_mass) == pytest.approx(32.0)


def test_link_lengths(model):
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("stand").id)
    mujoco.mj_forward(model, data)
    hip = data.site("hip").xpos
    assert data.site("head").xpos[2] - hip[2] == pytest.approx(0.63)  # torso
    for leg in ("left", "right"):
        knee = data.body(f"{leg}_tibia").xpos
        foot = data.site(f"{leg}_foot").xpos
        assert hip[2] - knee[2] == pytest.approx(0.4)  # femur
        assert knee[2] - foot[2] == pytest.approx(0.4)  # tibia


def test_standing_straight_puts_the_hip_at_080(model):
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("stand").id)
    mujoco.mj_forward(model, data)
    assert data.site("hip").xpos[2] == pytest.approx(0.80)
    assert data.site("head").xpos[2] == pytest.approx(1.43)  # tip of the torso (paper)
    for leg in ("left", "right"):
        assert data.site(f"{leg}_foot").xpos[2] == pytest.approx(0.0, abs=1e-12)
    # Let it settle on its straight legs (held by the knee limits): the feet carry it.
    for _ in range(500):
        mujoco.mj_step(model, data)
    assert data.qpos[1] == pytest.approx(0.80, abs=1e-3)


def test_only_the_feet_touch_the_ground(model):
    colliding = {model.geom(i).name for i in range(model.ngeom) if model.geom_contype[i] or model.geom_conaffinity[i]}
    assert colliding == {"floor", "left_foot", "right_foot"}


def test_torque_limits_and_actuator_order(model):
    assert tuple(model.actuator(i).name for i in range(model.nu)) == ACTUATED_JOINTS
    for i in range(model.nu):
        assert model.actuator_ctrllimited[i]
        np.testing.assert_allclose(model.actuator_ctrlrange[i], [-150.0, 150.0])
        assert model.actuator_gear[i][0] == 1.0
        assert model.joint(model.actuator_trnid[i][0]).name == ACTUATED_JOINTS[i]


def test_paper_variant_has_ideal_joints(model):
    for name in ACTUATED_JOINTS:
        j = model.joint(name)
        assert model.dof_armature[j.dofadr[0]] == 0.0
        assert model.dof_frictionloss[j.dofadr[0]] == 0.0


def test_drives_variant_reflects_rotor_inertia():
    params = DriveParameters()
    assert params.armature == pytest.approx(0.83, abs=1e-3)
    m = load_model("drives")
    for name in ACTUATED_JOINTS:
        dof = m.joint(name).dofadr[0]
        assert m.dof_armature[dof] == pytest.approx(3.32e-4 * 50**2)
        assert m.dof_frictionloss[dof] == pytest.approx(params.coulomb_friction)
        assert m.dof_damping[dof] == pytest.approx(params.viscous_friction)
    # The floating base is untouched.
    for name in ("x", "z", "torso_pitch"):
        assert m.dof_armature[m.joint(name).dofadr[0]] == 0.0


def test_unknown_variant_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown model variant"):
        load_model("nope")


def test_controller_kinematics_match_the_model(model):
    """The controller's pure kinematics and MuJoCo agree on where the feet are."""
    rng = np.random.default_rng(0)
    data = mujoco.MjData(model)
    geom = LegGeometry()
    for _ in range(50):
        q = [rng.uniform(-1, 1), rng.uniform(0.6, 0.8), rng.uniform(-0.4, 0.4),
             rng.uniform(-1, 1), rng.uniform(0, 1.5), rng.uniform(-1, 1), rng.uniform(0, 1.5)]
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for leg, (hip, knee) in (("left", q[3:5]), ("right", q[5:7])):
            fx, fz = foot_from_hip(geom, q[2], hip, knee)
            site = data.site(f"{leg}_foot").xpos
            assert site[0] == pytest.approx(q[0] + fx, abs=1e-12)
            assert site[2] == pytest.approx(q[1] + fz, abs=1e-12)


@pytest.mark.parametrize("start_steps, duration", [(1000, 0.1), (2345, 0.3), (7, 0.05)])
def test_a_push_lasts_its_duration_in_whole_steps(start_steps, duration):
    """Sim time sums 1 ms steps and drifts below exact values; a 0.1 s push is still
    exactly 100 steps of force, whenever it starts."""
    from rabbit_sim.physics.simulation import Simulator

    sim = Simulator(load_model("paper"))
    sim.reset([0.0, 0.75, 0.0, 0.3, 0.4, -0.2, 0.4], [0.0] * 7)
    for _ in range(start_steps):
        sim.step([0.0] * 4)
    sim.push(40.0, duration)
    pushed = 0
    while any(sim.push_wrench):
        sim.step([0.0] * 4)
        pushed += 1
    assert pushed == round(duration / sim.timestep)
    assert sim.push_wrench == (0.0, 0.0, 0.0)
