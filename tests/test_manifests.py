"""Each package.xml declares exactly what its package's code imports (as rosdep keys), so a
colcon/rosdep user gets every dependency and nothing unused: the venv hides a missing one."""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGES = ("rabbit_msgs_py", "rabbit_sim", "rabbit_hzd_controller", "rabbit_policy")

ROSDEP_KEYS = {
    # Python modules from PyPI / Debian -> rosdep keys
    # (keys as ros/rosdistro's rosdep/python.yaml names them: *-pip where only pip has it;
    # mcap has no key of its own, mcap-ros2-support installs it)
    "numpy": "python3-numpy", "numba": "python3-numba",
    "llvmlite": "python3-numba",  # numba's own compiler binding: no key of its own, numba's package brings it
    "mujoco": "python3-mujoco-pip", "PIL": "python3-pil",
    "matplotlib": "python3-matplotlib", "torch": "python3-torch", "gymnasium": "python3-gymnasium-pip",
    "rosbags": "python3-rosbags-pip", "yaml": "python3-yaml", "tqdm": "python3-tqdm", "mcap": "mcap-ros2-support",
    # ROS 2 packages: the key is the package name
    **{name: name for name in ("rclpy", "std_msgs", "sensor_msgs", "geometry_msgs", "rosgraph_msgs", "std_srvs",
                               "rcl_interfaces", "builtin_interfaces", "visualization_msgs")},
    **{name: name for name in PACKAGES},
}


# pip-only, no rosdep key in rosdistro: pinned in requirements.txt (cma) or
# requirements-extras.txt (ray, stable-baselines3) and imported only where needed
# (rabbit_policy.parallel for --backend ray; the gait optimizer for CMA-ES; the SB3 baseline,
# rabbit_policy.learning.sb3), so the packages run without them on a ROS install
OPTIONAL = {"ray", "cma", "stable_baselines3"}
ROSDISTRO_EXCERPT = Path(__file__).resolve().parent / "data" / "rosdep_python_excerpt.yaml"


def imported_modules(package: str) -> set[str]:
    """Top-level modules imported anywhere in the package's code (functions included)."""
    names: set[str] = set()
    for path in (SRC / package / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return {n for n in names if n not in sys.stdlib_module_names and n != package and n not in OPTIONAL}


def declared(package: str) -> set[str]:
    root = ET.parse(SRC / package / "package.xml").getroot()
    return {e.text.strip() for e in root if e.tag in ("depend", "exec_depend") and e.text}


@pytest.mark.parametrize("package", PACKAGES)
def test_package_xml_declares_what_the_code_imports(package):
    modules = imported_modules(package)
    unknown = sorted(m for m in modules if m not in ROSDEP_KEYS)
    assert not unknown, f"{package} imports {unknown}: add their rosdep keys to this test and package.xml"
    needed = {ROSDEP_KEYS[m] for m in modules}
    have = declared(package)
    assert not needed - have, f"{package}/package.xml lacks {sorted(needed - have)}"
    assert not have - needed, f"{package}/package.xml declares {sorted(have - needed)}, which nothing imports"


def test_the_shared_layer_and_the_simulator_import_no_controller_or_policy():
    assert not imported_modules("rabbit_msgs_py") & {"rabbit_sim", "rabbit_hzd_controller", "rabbit_policy"}
    assert not imported_modules("rabbit_sim") & {"rabbit_hzd_controller", "rabbit_policy"}


def test_the_tests_import_the_packages_from_src():
    """No test directory on the path shadows a package (a tests/rabbit_policy did: the
    package then resolved to a namespace without its data)."""
    import importlib

    for name in PACKAGES:
        module = importlib.import_module(name)
        assert module.__file__ and Path(module.__file__).resolve().is_relative_to(SRC / name), module


def test_every_python_rosdep_key_is_one_rosdistro_defines():
    """``rosdep install`` resolves every non-ROS key of every package.xml: each is an entry of
    rosdistro's rosdep/python.yaml (tests/data holds the entries, with the commit they are
    from) for Debian and Ubuntu."""
    import yaml

    entries = yaml.safe_load(ROSDISTRO_EXCERPT.read_text())
    assert "commit" in ROSDISTRO_EXCERPT.read_text().splitlines()[0]
    ros = {name for name, key in ROSDEP_KEYS.items() if name == key}
    for package in PACKAGES:
        for key in declared(package) - ros - {"python3-pytest"}:
            assert key in entries, f"{package}/package.xml: {key} is not a rosdep key in rosdistro"
            assert {"debian", "ubuntu"} <= set(entries[key]), f"{key} does not resolve on Debian and Ubuntu"


# what a pinned distribution is imported as, where the names differ; and the pins that are
# tools (run, not imported) or that come in through another import
IMPORT_NAMES = {"PyYAML": "yaml", "pillow": "PIL", "stable-baselines3": "stable_baselines3",
                "mcap-ros2-support": "mcap_ros2", "tensorboard": "torch.utils.tensorboard"}
TOOLS = {"colcon-common-extensions", "pytest", "pytest-xdist", "ruff", "ros-jazzy-rclpy", "ros-rclpy",
         "ros-jazzy-common-interfaces"}


def test_every_pin_is_imported_somewhere():
    """requirements*.txt pin nothing unused (a scipy pin once stood there, imported nowhere):
    every pinned distribution but the tools is imported by the packages, scripts or tests."""
    root = SRC.parent
    pins = []
    for name in ("requirements.txt", "requirements-extras.txt"):
        for line in (root / name).read_text().splitlines():
            line = line.split("#")[0].strip()
            if line:
                pins.append(line.split("==")[0].split("[")[0])
    imported: set[str] = set()
    for path in [*SRC.rglob("*.py"), *(root / "scripts").glob("*.py"), *(root / "tests").rglob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                imported.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                imported.add(node.module)
    prefixes = {m.split(".")[0] for m in imported} | imported
    unused = [p for p in pins if p not in TOOLS and IMPORT_NAMES.get(p, p) not in prefixes]
    assert not unused, f"pinned but imported nowhere: {unused}"
    from rabbit_policy.parallel import RAY_PIN

    assert RAY_PIN in (root / "requirements-extras.txt").read_text()  # the pin --backend ray's error names


def test_a_command_that_needs_a_missing_optional_dependency_says_so_in_one_line(tmp_path):
    """stable-baselines3 and Ray are optional (requirements-extras.txt): without them
    train_sb3.py and --backend ray are one line and exit 2."""
    import subprocess

    root = SRC.parent
    code = ("import runpy, sys; sys.modules['stable_baselines3'] = None; sys.modules['ray'] = None; "
            "sys.argv = sys.argv[1:]; runpy.run_path(sys.argv[0], run_name='__main__')")
    for script, args in (("train_sb3.py", ["--out", str(tmp_path / "sb3")]),
                         ("train.py", ["--algo", "es", "--out", str(tmp_path / "es"), "--backend", "ray", "--iterations", "1"])):
        out = subprocess.run([sys.executable, "-c", code, str(root / "scripts" / script), *args],
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 2 and out.stderr.count("\n") == 1, (script, out.stderr[-1500:])
        assert ("stable-baselines3" if script == "train_sb3.py" else "ray") in out.stderr
