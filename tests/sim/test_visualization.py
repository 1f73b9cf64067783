"""Seeing the robot: ``/rabbit/markers`` recorded in a bag and drawn to a PNG that matches
MuJoCo's bodies at the same ticks; MuJoCo's viewer under Xvfb (a screenshot of its window
shows the robot; results unchanged; a clear error without a display)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import mujoco
import numpy as np
import pytest
from PIL import Image

from rabbit_policy.bringup.config import StackConfig

from rabbit_policy.bringup.in_process import run_in_process
from rabbit_policy.experiment.scenario import Push
from rabbit_sim.marker_plot import render_png
from rabbit_sim.stepping.markers import PUSH_ID, RobotShapes, marker_period_ticks
from rabbit_sim.physics.model import load_model
from rabbit_sim.physics.simulation import Simulator

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    """A recorded 2 s lockstep run with a push at 1.0-1.1 s (markers at the default 30 Hz)."""
    path = tmp_path_factory.mktemp("viz") / "bag"
    report, _nodes = run_in_process(StackConfig(duration=2.0, schedule=((0.0, 1.0),), record=str(path),
                                                pushes=(Push(1.0, 60.0, 0.1),)))
    assert report.completed and not report.fell
    return path


def _read(bag: Path) -> tuple[list, dict[int, np.ndarray]]:
    """(marker messages, qpos of /joint_states by stamp in ns)."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    markers, states = [], {}
    with Reader(bag) as reader:
        for connection, _t, raw in reader.messages():
            if connection.topic == "/rabbit/markers":
                markers.append(store.deserialize_cdr(raw, connection.msgtype))
            elif connection.topic == "/joint_states":
                msg = store.deserialize_cdr(raw, connection.msgtype)
                states[msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec] = np.array(msg.position)
    return markers, states


def test_marker_rate_and_shapes_follow_the_model():
    model = load_model("paper")
    assert marker_period_ticks(30.0, 0.001) == 33 and marker_period_ticks(0.0, 0.001) == 0
    with pytest.raises(ValueError):
        marker_period_ticks(-1.0, 0.001)
    shapes = RobotShapes(model)
    assert shapes.names == ["torso", "left_femur", "left_tibia", "left_foot", "right_femur", "right_tibia",
                            "right_foot"]
    sim = Simulator(model)
    sim.push(50.0, 0.1)
    mujoco.mj_forward(model, sim.data)
    by_name = {s.name: s for s in shapes.shapes(sim.data)}
    assert by_name["left_tibia"].kind == "cylinder" and by_name["left_tibia"].scale == pytest.approx((0.04, 0.04, 0.38))
    assert by_name["push"].kind == "arrow"
    end = np.array(by_name["push"].points[1])
    assert np.allclose(end, sim.data.xipos[model.body("torso").id])  # the arrow ends at the torso's CoM


@pytest.mark.slow
def test_recorded_markers_render_to_a_png_matching_mujoco_bodies(bag, tmp_path):
    markers, states = _read(bag)
    assert 60 <= len(markers) <= 62  # 2 s at 30 Hz, and one when RABBIT is placed
    model = load_model("paper")
    data = mujoco.MjData(model)
    body = {name: model.body(name).id for name in ("torso", "left_femur", "left_tibia", "right_femur", "right_tibia")}
    pushes = 0
    for msg in markers[:: len(markers) // 6]:
        stamp = msg.markers[0].header.stamp
        assert msg.markers[0].header.frame_id == "world"
        data.qpos[:] = states[stamp.sec * 10**9 + stamp.nanosec]  # the state of the same tick
        mujoco.mj_kinematics(model, data)
        drawn, to_pixel = render_png(msg.markers, tmp_path / "frame.png")
        links = {d.id: d for d in drawn if d.kind == "cylinder"}
        xz = {name: data.xpos[i][[0, 2]] for name, i in body.items()}  # the hip is the torso body's origin
        def has_end(link, point) -> bool:
            return any(np.allclose(end, point, atol=1e-6) for end in link.points)

        for leg in ("left", "right"):
            femur, tibia = links[model.geom(f"{leg}_femur").id], links[model.geom(f"{leg}_tibia").id]
            assert has_end(femur, xz["torso"]) and has_end(femur, xz[f"{leg}_tibia"])  # hip to knee
            assert has_end(tibia, xz[f"{leg}_tibia"])  # from the knee
        assert has_end(links[model.geom("torso").id], xz["torso"])  # from the hip
        pushes += any(d.kind == "arrow" for d in drawn)
        # the PNG shows each link in its colour at its midpoint (those not covered by another link)
        image = np.asarray(Image.open(tmp_path / "frame.png").convert("RGB")) / 255.0
        matched = 0
        for d in links.values():
            col, row = to_pixel(*np.mean(d.points, axis=0))
            matched += np.allclose(image[row, col], d.rgba[:3], atol=0.02)
        assert matched >= len(links) - 1, f"{matched} of {len(links)} links drawn where MuJoCo has them"
    push_frames = [m for m in markers if any(x.id == PUSH_ID and x.action == 0 for x in m.markers)]
    assert push_frames and all(1.0 <= m.markers[0].header.stamp.sec + m.markers[0].header.stamp.nanosec * 1e-9
                                <= 1.1 + 1e-6 for m in push_frames)


# ------------------------------------------------------------------ MuJoCo's viewer
@pytest.mark.slow
def test_viewer_window_shows_the_robot(display):
    """``walk.py --viewer`` (its own process: the test process never holds an X connection
    that the display's end would break) draws RABBIT: the torso's and the right leg's
    colours appear in a screenshot of the display, and were not there before."""
    from PIL import ImageGrab

    def colour_pixels(image: np.ndarray, rgb: tuple[float, float, float]) -> int:
        return int(np.all(np.abs(image - rgb) < 0.2, axis=2).sum())

    blank = np.asarray(ImageGrab.grab(xdisplay=display).convert("RGB")).astype(float) / 255.0
    walker = subprocess.Popen([sys.executable, "scripts/walk.py", "--speed", "1.0", "--duration", "60", "--viewer"],
                              cwd=ROOT, env={**os.environ, "DISPLAY": display}, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        torso = right = 0
        while time.monotonic() < deadline and walker.poll() is None and not (torso > 200 and right > 200):
            time.sleep(0.5)  # until the window has drawn the robot (software GL is slow on a loaded machine)
            image = np.asarray(ImageGrab.grab(xdisplay=display).convert("RGB")).astype(float) / 255.0
            torso, right = colour_pixels(image, (0.75, 0.6, 0.3)), colour_pixels(image, (0.8, 0.35, 0.3))
    finally:
        walker.terminate()
        _out, err = walker.communicate(timeout=30)
    assert colour_pixels(blank, (0.75, 0.6, 0.3)) == 0  # nothing of the robot's colour before
    assert torso > 200 and right > 200, f"torso {torso} px, right leg {right} px in the viewer's window; {err[-500:]}"


def _walk(*extra: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "scripts/walk.py", "--speed", "1.1", "--duration", "1.5", "--push",
                           "0.8:40:0.1", "--json", *extra], capture_output=True, text=True, cwd=ROOT, timeout=300,
                          env=env)


@pytest.mark.slow
def test_walk_viewer_leaves_results_unchanged_and_needs_a_display(display):
    plain = json.loads(_walk().stdout)
    viewed = _walk("--viewer", env={**os.environ, "DISPLAY": display})
    assert viewed.returncode == 0, viewed.stderr
    seen = json.loads(viewed.stdout)
    for result in (plain, seen):
        result.pop("real_time_factor"), result.pop("wall_time")
    assert seen == plain
    headless = _walk("--viewer", env={k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")})
    assert headless.returncode == 2 and headless.stderr.strip().startswith("error: the viewer needs a display")


@pytest.mark.slow
def test_sim_node_viewer_leaves_the_lockstep_run_unchanged(display):
    def run(*extra: str, env: dict) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "scripts/run_stack.py", "--duration", "1.5", "--in-process", "--json",
                               "--push", "0.8:40:0.1", *extra], capture_output=True, text=True, cwd=ROOT,
                              timeout=300, env=env)

    plain = run(env=dict(os.environ))
    viewed = run("--viewer", env={**os.environ, "DISPLAY": display})
    assert plain.returncode == 0 and viewed.returncode == 0, viewed.stderr[-2000:]
    drop = ("real_time_factor", "wall_time")
    assert ({k: v for k, v in json.loads(viewed.stdout).items() if k not in drop}
            == {k: v for k, v in json.loads(plain.stdout).items() if k not in drop})
    headless = run("--viewer", env={k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")})
    assert headless.returncode == 2 and headless.stderr.strip().startswith("error: the viewer needs a display")


def test_foxglove_layout_uses_only_topics_and_fields_that_exist():
    """Every message path of docs/foxglove_layout.json names a stack topic and a field of its
    message type (index into a sequence; header stamps only where the message has one)."""
    import re

    from rabbit_msgs_py import topics
    from rabbit_msgs_py.catalog import STACK_TOPICS

    specs = {topics.resolve(name): spec for name, spec in STACK_TOPICS.items()}  # the layout's: the root namespace
    layout = json.loads((ROOT / "docs" / "foxglove_layout.json").read_text())
    paths = [p for panel in layout["configById"].values() for p in panel.get("paths", [])]
    assert len(paths) >= 12
    for path in paths:
        topic = next(t for t in sorted(specs, key=len, reverse=True) if path["value"].startswith(t + "."))
        value = specs[topic].msg_class()
        if path["timestampMethod"] == "headerStamp":
            assert hasattr(value, "header"), path
        for field, index in re.findall(r"\.(\w+)(?:\[(\d+)\])?", path["value"][len(topic):]):
            value = getattr(value, field)
            if index:
                assert hasattr(value, "__len__"), path
                value = 0.0
    assert layout["configById"]["3D!rabbit"]["topics"] == {"/rabbit/markers": {"visible": True}}
    panels = json.dumps(layout["layout"])
    assert all(name in panels for name in layout["configById"])  # every panel is placed


# ------------------------------------------------------------------ the URDF on /robot_description
def test_the_recorded_robot_description_is_a_urdf_whose_kinematics_are_mujocos(bag):
    """sim_node's /robot_description (recorded: transient local, as robot_state_publisher
    offers it) parses with yourdfpy, a maintained URDF library; for recorded /joint_states
    (a walk with a push) every link frame and foot from the URDF's forward kinematics is where
    MuJoCo puts the body (1e-9 m, 1e-9 rotation)."""
    import io

    import yourdfpy
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    descriptions, states = [], []
    with Reader(bag) as reader:
        for connection, _t, raw in reader.messages():
            if connection.topic == "/robot_description":
                descriptions.append(store.deserialize_cdr(raw, connection.msgtype).data)
            elif connection.topic == "/joint_states":
                states.append(store.deserialize_cdr(raw, connection.msgtype))
    assert len(descriptions) == 1 and len(states) > 1500
    robot = yourdfpy.URDF.load(io.StringIO(descriptions[0]), load_meshes=False)
    assert robot.validate()
    model = load_model("paper")
    data = mujoco.MjData(model)
    bodies = ("torso", "left_femur", "left_tibia", "right_femur", "right_tibia")
    assert set(robot.actuated_joint_names) == set(states[0].name)
    for msg in states[::50]:
        robot.update_cfg(dict(zip(msg.name, msg.position)))
        data.qpos[:] = msg.position  # /joint_states is in qpos order (JOINT_NAMES)
        mujoco.mj_kinematics(model, data)
        for body in bodies:
            pose = robot.get_transform(body, "world")
            assert np.allclose(pose[:3, 3], data.xpos[model.body(body).id], atol=1e-9), body
            assert np.allclose(pose[:3, :3], data.xmat[model.body(body).id].reshape(3, 3), atol=1e-9), body
        for foot in ("left_foot", "right_foot"):
            assert np.allclose(robot.get_transform(foot, "world")[:3, 3], data.site_xpos[model.site(foot).id],
                               atol=1e-9)
