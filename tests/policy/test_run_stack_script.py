"""scripts/run_stack.py as users run it: the nodes as separate processes, JSON out, and
Ctrl-C (SIGINT) stopping everything cleanly with a partial report."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from proc_helpers import children

pytestmark = [pytest.mark.ros, pytest.mark.slow]

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "run_stack.py"


def _node_processes(parent: int) -> list[str]:
    """Command lines of the node processes run_stack (pid ``parent``) started, or of any
    still alive that it had started (``started``)."""
    return children(parent, "-m rabbit_")


NODE_PROCESSES = {"composed": 1, "separate": 3}
"""Node processes run_stack starts in each layout: composed (the default) runs the simulator and
the controller in its own process, and starts the policy; separate starts all three."""


def _alive(pids: list[str]) -> list[str]:
    return [pid for pid in pids if Path(f"/proc/{pid}").exists()]


def test_multi_process_run_reports_json():
    result = subprocess.run(
        [sys.executable, str(SCRIPT), "--speed", "1.0", "--duration", "3", "--json"],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads(result.stdout)
    assert report["fell"] is False and report["completed"] is True
    assert report["real_time_factor"] > 0.0  # a number; how fast depends on the machine (scripts/bench_stack.py)
    assert report["segments"][0]["command"] == 1.0
    assert abs(report["segments"][0]["mean_speed"] - 1.0) < 0.1
    assert report["rejected"] == 0  # the controller process's own count (its stats file), not null


def test_bad_arguments_with_json_print_the_report_too():
    result = subprocess.run([sys.executable, str(SCRIPT), "--speed", "fast", "--json"], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 2 and "--speed" in result.stderr
    report = json.loads(result.stdout)
    assert report["completed"] is False and report["error"].startswith("bad arguments") and report["rejected"] == 0
    for args, error in ((["--speed-schedule", "0:1.0,1:x"], "speed"), (["--spec", "/nonexistent.yaml"], "nonexistent")):
        result = subprocess.run([sys.executable, str(SCRIPT), *args, "--json"], capture_output=True, text=True,
                                timeout=120)
        assert result.returncode == 2, result.stderr[-2000:]
        report = json.loads(result.stdout)
        assert report["completed"] is False and error in report["error"], report["error"]


def test_a_lone_publisher_of_our_topics_does_not_stop_a_start():
    """A node that only publishes /joint_torques (a test tool; play.py replaying a bag) is not
    a stack: run_stack starts beside it and walks."""
    tool = subprocess.Popen([sys.executable, "-c", (
        "import rclpy, time\n"
        "from rabbit_msgs_py.node_runner import init_context\n"
        "from sensor_msgs.msg import JointState\n"
        "context = init_context()\n"
        "node = rclpy.create_node('torque_tool', context=context)\n"
        "node.create_publisher(JointState, '/joint_torques', 10)\n"
        "print('up', flush=True)\n"
        "time.sleep(120)\n")], stdout=subprocess.PIPE, text=True)
    try:
        assert tool.stdout.readline().strip() == "up"
        time.sleep(1.0)  # discovered
        run = subprocess.run([sys.executable, str(SCRIPT), "--speed", "1.0", "--duration", "2", "--json"],
                             capture_output=True, text=True, timeout=120)
    finally:
        tool.kill()
        tool.wait()
    assert run.returncode == 0, run.stderr[-2000:]
    assert json.loads(run.stdout)["completed"] is True


@pytest.mark.parametrize("layout", ["composed", "separate"])
def test_ctrl_c_stops_the_nodes_and_prints_what_was_measured(layout):
    """Lockstep (the mode that holds on any machine): Ctrl-C once the simulation runs."""
    proc = subprocess.Popen(
        [sys.executable, str(SCRIPT), "--speed", "1.0", "--duration", "600", "--json", "--layout", layout],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    lines: list[str] = []
    running = threading.Event()

    def read_stderr() -> None:
        for line in proc.stderr:
            lines.append(line)
            if "simulation running" in line:
                running.set()

    reader = threading.Thread(target=read_stderr, daemon=True)
    reader.start()
    try:
        assert running.wait(120), "".join(lines)[-2000:]
        children = _node_processes(proc.pid)
        assert len(children) == NODE_PROCESSES[layout]
        time.sleep(1.0)  # walk a little
        proc.send_signal(signal.SIGINT)
        out = proc.stdout.read()
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    reader.join(timeout=10)
    err = "".join(lines)
    assert proc.returncode == 3, err[-2000:]
    report = json.loads(out)
    assert report["error"] == "interrupted" and report["completed"] is False
    # how much sim time 1 s of wall time buys depends on the machine: under load (two busy
    # loops beside the suite) the interrupt came before the first state (CI read 0.0 s once)
    assert 0.0 <= report["duration"] < 600.0
    assert report["segments"][0]["mean_speed"] is None  # cut short: no mean for the segment it was in
    assert _alive(children) == []
    assert "Traceback" not in err and "FATAL" not in err


@pytest.mark.parametrize("delay", [1.5, 3.0, "nodes importing", "nodes importing + 1 s"])
def test_ctrl_c_during_start_up_gives_exit_3_and_an_interrupted_report(delay):
    """Ctrl-C while run_stack starts (its checks, the 3 s probe for another stack, the nodes
    coming up: the moment depends on the machine, the outcome must not). "nodes importing":
    as soon as the node processes exist, while they import (once 1-3 KeyboardInterrupt
    tracebacks of 38-105 lines in 6 of 12 runs)."""
    proc = subprocess.Popen([sys.executable, str(SCRIPT), "--speed", "1.0", "--duration", "600", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        if isinstance(delay, str):
            deadline = time.monotonic() + 60.0
            while len(_node_processes(proc.pid)) < NODE_PROCESSES["composed"] and time.monotonic() < deadline:
                time.sleep(0.02)
            time.sleep(1.0 if delay.endswith("1 s") else 0.0)
        else:
            time.sleep(delay)
        children = _node_processes(proc.pid)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 3, err[-2000:]
    report = json.loads(out)
    assert report["error"] == "interrupted" and report["completed"] is False
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert _alive(children + _node_processes(proc.pid)) == []


def test_stacks_in_two_namespaces_run_side_by_side_and_a_second_in_one_namespace_is_refused():
    """One domain: a stack in /rabbit1 walks at 0.8 m/s; a second in /rabbit1 is refused with
    one line; a stack in /rabbit2 walks at 1.3 m/s beside the first (every topic and service
    relative, so neither hears the other's speed command or torques), then the first is
    stopped: it never fell."""
    first = subprocess.Popen([sys.executable, str(SCRIPT), "--speed", "0.8", "--duration", "600", "--json",
                              "--namespace", "rabbit1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while len(_node_processes(first.pid)) < NODE_PROCESSES["composed"] and time.monotonic() < deadline:
            time.sleep(0.2)
        time.sleep(2.0)  # let its nodes come up and be discovered
        clash = subprocess.run([sys.executable, str(SCRIPT), "--speed", "1.2", "--duration", "2", "--json",
                                "--namespace", "/rabbit1"], capture_output=True, text=True, timeout=120)
        assert clash.returncode == 2, clash.stderr[-2000:]
        lines = clash.stderr.strip().splitlines()
        assert len(lines) == 1 and "another rabbit-hzd stack runs in namespace /rabbit1 of ROS_DOMAIN_ID=" in lines[0]
        refused = json.loads(clash.stdout)  # --json: every exit prints the report
        assert refused["completed"] is False and "another rabbit-hzd stack runs" in refused["error"]
        beside = subprocess.run([sys.executable, str(SCRIPT), "--speed", "1.3", "--duration", "6", "--json",
                                 "--namespace", "rabbit2"], capture_output=True, text=True, timeout=180)
        assert beside.returncode == 0, beside.stderr[-2000:]
        report = json.loads(beside.stdout)
        assert report["completed"] and not report["fell"]
        assert abs(report["segments"][0]["mean_speed"] - 1.3) < 0.1
        left_alone = first.poll() is None  # the first one was left alone
    finally:
        first.send_signal(signal.SIGINT)
        out, err = first.communicate(timeout=60)
    assert left_alone, (out, "\n".join(line for line in err.splitlines() if "[INFO]" not in line)[-6000:])
    report = json.loads(out)
    assert report["fell"] is False and report["duration"] > 1.0, err[-2000:]


@pytest.mark.parametrize("layout", ["separate", "composed"])
def test_a_run_stack_killed_outright_takes_its_nodes_with_it_quietly(layout):
    """SIGKILL to run_stack mid-walk (no chance to stop its nodes, as a test's timeout or the
    OOM killer does): its node processes end too, so no stack is left running in the domain,
    and they end quietly: nothing they write after the kill is a traceback or an abort
    ("terminate called", "Fatal Python error"). Their stderr is run_stack's, so its end of
    file is the last of them closing it."""
    first = subprocess.Popen([sys.executable, str(SCRIPT), "--controller", "learned", "--speed", "1.0",
                              "--duration", "600", "--layout", layout], stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    lines: list[tuple[float, str]] = []
    reader = threading.Thread(target=lambda: lines.extend((time.monotonic(), line) for line in first.stderr),
                              daemon=True)
    reader.start()
    deadline = time.monotonic() + 60
    nodes: list[str] = []
    while len(nodes) < NODE_PROCESSES[layout] and time.monotonic() < deadline:
        time.sleep(0.2)
        nodes = _node_processes(first.pid)
    assert len(nodes) == NODE_PROCESSES[layout]
    while not any("paired with controller" in line for _, line in list(lines)) and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(2.0)  # the walk under way (a kill at any moment must be quiet; this one is mid-walk)
    killed = time.monotonic()
    first.kill()
    first.wait()

    def running(pid: str) -> bool:  # alive and not a zombie waiting to be reaped
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
        except OSError:
            return False

    deadline = time.monotonic() + 30
    while any(running(pid) for pid in nodes) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(running(pid) for pid in nodes), [pid for pid in nodes if running(pid)]
    reader.join(30)
    assert not reader.is_alive()  # every child closed the stderr it shared with run_stack
    after = "".join(line for t, line in list(lines) if t >= killed)
    for trace in ("Traceback", "terminate called", "Fatal Python error", "Aborted"):
        assert trace not in after, after[-3000:]


def test_a_run_that_simulated_nothing_prints_no_nan(capsys):
    """The report of a run stopped before the simulation moved (a node that never came up,
    Ctrl-C at once) says what happened and prints no nan: no real-time factor, no mean."""
    import numpy as np

    from rabbit_policy.bringup.config import StackConfig

    from rabbit_policy.bringup.supervisor import RunReport
    from rabbit_policy.experiment.result import WalkResult
    from rabbit_policy.experiment.scenario import Scenario

    from rabbit_policy.commands import run_stack  # scripts/run_stack.py's own code

    nothing = WalkResult(Scenario.constant(1.0), fell=False, fall_time=None, stalled=False, stall_time=None,
                         start_time=0.0, start_x=0.0, times=np.array([]), hip_x=np.array([]))
    report = RunReport("classic", None, nothing, wall_time=0.0, completed=False, error="interrupted")
    run_stack.print_report(report, StackConfig(duration=2.0, schedule=((0.0, 1.0),)))
    out = capsys.readouterr().out
    assert "nan" not in out.lower() and "simulated    nothing" in out and "interrupted" in out
    assert json.dumps(report.summary(), allow_nan=False)
