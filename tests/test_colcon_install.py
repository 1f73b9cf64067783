"""The four packages build with colcon (from PyPI) into a ROS-style install space: the ament
index lists them and each node's executable sits at install/<pkg>/lib/<pkg>/<node>,
where ``ros2 run`` looks for it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rabbit_msgs_py", "rabbit_sim", "rabbit_hzd_controller", "rabbit_policy")
NODES = (
    ("rabbit_sim", "sim_node"),
    ("rabbit_sim", "recorder_node"),
    ("rabbit_hzd_controller", "hzd_controller_node"),
    ("rabbit_policy", "policy_node"),
    ("rabbit_policy", "walk"),  # the command lines too: ros2 run rabbit_policy walk / run_stack / set_speed
    ("rabbit_policy", "run_stack"),
    ("rabbit_policy", "set_speed"),
)


@pytest.fixture(scope="module")
def install_space(tmp_path_factory) -> Path:
    colcon = Path(sys.executable).parent / "colcon"
    if not colcon.exists():
        colcon = shutil.which("colcon")
    assert colcon, "colcon is missing: it is in requirements.txt (colcon-common-extensions)"
    base = tmp_path_factory.mktemp("colcon")
    result = subprocess.run(
        [str(colcon), "--log-base", str(base / "log"), "build", "--base-paths", str(ROOT / "src"),
         "--build-base", str(base / "build"), "--install-base", str(base / "install")],
        cwd=base, capture_output=True, text=True, timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return base / "install"


def test_ament_index_lists_the_packages_and_nodes(install_space):
    from ament_index_python.packages import get_package_prefix, get_packages_with_prefixes

    prefixes = os.pathsep.join(str(install_space / p) for p in PACKAGES)
    old = os.environ.get("AMENT_PREFIX_PATH")
    os.environ["AMENT_PREFIX_PATH"] = prefixes
    try:
        found = get_packages_with_prefixes()
        for package in PACKAGES:
            assert Path(found[package]) == install_space / package
        for package, node in NODES:
            executable = Path(get_package_prefix(package)) / "lib" / package / node  # ros2 run's lookup
            assert executable.is_file() and os.access(executable, os.X_OK)
    finally:
        if old is None:
            del os.environ["AMENT_PREFIX_PATH"]
        else:
            os.environ["AMENT_PREFIX_PATH"] = old


def test_the_installed_walk_command_walks(install_space):
    """``ros2 run rabbit_policy walk ...``: the installed command line is scripts/walk.py's."""
    executable = install_space / "rabbit_policy" / "lib" / "rabbit_policy" / "walk"
    # as `source install/setup.bash` would: the install space's packages first on the path
    site = [str(p) for p in sorted(install_space.glob("*/lib/python3*/site-packages"))]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(site + [os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run([str(executable), "--duration", "1", "--json"], capture_output=True, text=True,
                            timeout=120, env=env)
    assert result.returncode == 0, result.stderr
    assert '"fell": false' in result.stdout
    bad = subprocess.run([str(executable), "--speed", "nan"], capture_output=True, text=True, timeout=120, env=env)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1


def test_installed_executable_runs_and_reports_bad_parameters(install_space):
    executable = install_space / "rabbit_sim" / "lib" / "rabbit_sim" / "sim_node"
    result = subprocess.run(
        [str(executable), "--ros-args", "-p", "mode:=bogus"],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 1
    assert "mode must be one of" in result.stdout + result.stderr


def test_parameters_from_a_params_file_and_the_command_line(tmp_path):
    params = tmp_path / "policy.yaml"
    params.write_text("policy_node:\n  ros__parameters:\n    policy: learned\n    policy_file: /nonexistent/p.pt\n")
    result = subprocess.run(
        [sys.executable, "-m", "rabbit_policy.policy_node", "--ros-args", "--params-file", str(params)],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 1 and "policy file /nonexistent/p.pt does not exist" in result.stdout
    result = subprocess.run(
        [sys.executable, "-m", "rabbit_policy.policy_node", "--ros-args", "-p", "min_speed:=1.4", "-p",
         "max_speed:=1.2"],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 1 and "min_speed (1.4) must not be above max_speed" in result.stdout


def test_the_install_space_carries_the_package_data(install_space):
    """The gait library, the shipped specs with their weights, and the learned one's model card are installed."""
    site = list((install_space / "rabbit_policy" / "lib").glob("python3*/site-packages/rabbit_policy"))
    assert len(site) == 1, site
    packaged = sorted(p.name for p in (Path(__file__).resolve().parents[1] / "src" / "rabbit_policy" / "rabbit_policy"
                                       / "gaits").glob("*.json"))
    assert sorted(p.name for p in (site[0] / "gaits").glob("*.json")) == packaged  # gaits + interpolation.json
    assert "interpolation.json" in packaged and len(packaged) == 12
    for name in ("MODEL_CARD.md", "evaluation.json"):
        assert (site[0] / "trained" / name).is_file(), name
    specs = Path(__file__).resolve().parents[1] / "src" / "rabbit_policy" / "rabbit_policy" / "controllers"
    shipped = sorted(p.name for p in specs.iterdir() if p.suffix in (".yaml", ".npz"))
    assert sorted(p.name for p in (site[0] / "controllers").iterdir()) == shipped  # the specs and their weights
    assert {"classic.yaml", "recovery.yaml", "learned.yaml"} <= set(shipped)


def test_the_urdf_is_installed_where_ros_tools_look_for_it(install_space):
    """share/rabbit_sim/urdf/rabbit.urdf (``$(find-pkg-share rabbit_sim)/urdf/rabbit.urdf``), and
    inside the Python package, where sim_node and scripts find it."""
    from rabbit_sim.urdf import packaged_urdf

    assert (install_space / "rabbit_sim" / "share" / "rabbit_sim" / "urdf" / "rabbit.urdf").read_text() == packaged_urdf()
    site = list((install_space / "rabbit_sim" / "lib").glob("python3*/site-packages/rabbit_sim/urdf/rabbit.urdf"))
    assert len(site) == 1 and site[0].read_text() == packaged_urdf()
