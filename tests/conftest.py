"""Test-session environment and tiers.

Every ROS process in the tests discovers on localhost only
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST unless set) and uses a domain ID of its own, so
concurrent runs do not cross-talk; under pytest-xdist (``make test``: two workers) each worker
takes the next domain ID after the session's random one. A domain where some process already
runs a node (a stack left running by hand, another checkout's tests) is passed over, with a
warning in the session's summary: worker k of N takes the first free one of k, k + N, k + 2N, ... after the random one.
Each test process has a ROS home of its own (``ROS_HOME``, a fresh temporary directory: the
nodes' per-user pairing key and ROS's logs go there, never into the user's ``~/.ros``).
After every ros test the domain is probed again: if a node still runs there (a test's process
that outlived it, or one from outside), the worker moves to its next free domain and a warning
names the test and the nodes.

Layout: ``tests/{msgs,hzd_controller,sim,policy}/`` hold the tests of the ``rabbit_*`` package of
that name (without the prefix: ``tests/rabbit_sim`` on the path would shadow the package); ``tests/`` itself
the project-wide ones (manifests, the colcon build, the ROS wheels, the docs).

Tiers (markers, declared in pytest.ini), each set where the test is defined: a module's
``pytestmark`` gives its kind — ``unit`` (no simulation, no ROS), ``sim`` (real MuJoCo
walks, no ROS) or ``ros`` (real rclpy nodes or node processes) — or, in a module without
one, each test marks itself; a test has exactly one kind. ``slow``: a test over about 0.7 s on a slow 2-core machine (raw
mj_step ~110k steps/s) marks itself ``@pytest.mark.slow`` (or its whole module does);
``make test-fast`` leaves them out.
"""

import os
import random
import shutil
import subprocess
import tempfile
import warnings

import pytest

from rabbit_msgs_py.environment import ensure_localhost_discovery

ensure_localhost_discovery()  # before rclpy starts (ros_helpers imports it)
from ros_helpers import free_domain, next_domain  # noqa: E402
os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 101)))
_worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:])  # pytest -n N: a domain per worker
_workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
_domain, _busy = free_domain((int(os.environ["ROS_DOMAIN_ID"]) - 1 + _worker) % 101 + 1, stride=_workers)
os.environ["ROS_DOMAIN_ID"] = str(_domain)  # worker k takes k, k + N, k + 2N, ...: never another's
os.environ["ROS_HOME"] = tempfile.mkdtemp(prefix="rabbit-hzd-ros-home-")  # the pairing key and logs, per process

KINDS = ("unit", "sim", "ros")


def pytest_configure(config):
    """The compiled kernels built (or loaded from their cache) once, before any worker or node
    process starts: a cold cache would otherwise compile in each of them at once."""
    if not hasattr(config, "workerinput"):  # the controlling process (or a run without workers)
        from rabbit_policy.experiment.loop import compile_kernels

        compile_kernels()


def pytest_collection_modifyitems(config, items):
    """Each test has exactly one kind, set where it is defined (its module or itself)."""
    for item in items:
        kinds = {m.name for m in item.iter_markers() if m.name in KINDS}
        if len(kinds) != 1:
            raise pytest.UsageError(f"{item.nodeid}: give it one kind of {KINDS} (its module's pytestmark or "
                                    f"its own mark), not {sorted(kinds) or 'none'}")


@pytest.fixture(scope="session", autouse=True)
def _say_which_domains_were_busy():
    """A warning in the session's summary for each busy domain passed over (pytest, under
    xdist too, shows no output from the time this file is imported)."""
    for domain, users in _busy.items():
        warnings.warn(f"ROS_DOMAIN_ID={domain} is in use ({', '.join(users[:4])}); this test process "
                      f"uses {_domain}")
    yield


@pytest.fixture(autouse=True)
def _leave_no_node_to_the_next_test(request):
    """After each ros test: if any node runs in this process's domain (one the test left, or
    a process from outside), the following tests move to the next free domain of this
    worker's class, and a warning names the test and the nodes (the leak to look for)."""
    yield
    if request.node.get_closest_marker("ros") is None:
        return
    current = int(os.environ["ROS_DOMAIN_ID"])
    new, users, _ = next_domain(current, max(_workers, 1))
    if users:
        os.environ["ROS_DOMAIN_ID"] = str(new)
        warnings.warn(f"after {request.node.nodeid}: nodes still run in ROS_DOMAIN_ID={current} "
                      f"({', '.join(users[:6])}); the next tests of this process use {new}")


@pytest.fixture(scope="session")
def display():
    """A virtual X display (Xvfb) for the viewer tests (its name, e.g. ``:99``)."""
    if shutil.which("Xvfb") is None:
        pytest.fail("Xvfb is missing: apt-get install xvfb (.ci/run installs it)")
    read, write = os.pipe()
    server = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", "800x600x24", "-nolisten", "tcp"],
                              pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write)
    with os.fdopen(read) as f:
        number = f.readline().strip()
    try:
        yield f":{number}"
    finally:
        server.terminate()
        server.wait(timeout=10)
