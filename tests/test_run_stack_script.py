"""scripts/run_stack.py as users run it: the nodes as separate processes, JSON out, and
Ctrl-C (SIGINT) stopping everything cleanly with a partial report."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "run_stack.py"


def _node_processes(parent: int) -> list[str]:
    """Command lines of the node processes run_stack (pid ``parent``) started, or of any
    still alive that it had started (``started``)."""
    out = subprocess.run(["ps", "-eo", "pid=,ppid=,args="], capture_output=True, text=True).stdout
    rows = [line.split(None, 2) for line in out.splitlines()]
    return [row[0] for row in rows if len(row) == 3 and row[1] == str(parent) and "-m rabbit_" in row[2]]


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
    assert report["rtf"] > 0.5
    assert report["segments"][0]["command"] == 1.0
    assert abs(report["segments"][0]["mean_speed"] - 1.0) < 0.1


def test_ctrl_c_stops_the_nodes_and_prints_what_was_measured():
    proc = subprocess.Popen(
        [sys.executable, str(SCRIPT), "--speed", "1.0", "--duration", "60", "--mode", "realtime", "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    deadline = time.monotonic() + 30
    while len(_node_processes(proc.pid)) < 3 and time.monotonic() < deadline:
        time.sleep(0.2)
    children = _node_processes(proc.pid)
    assert len(children) == 3
    time.sleep(6.0)  # let it start (imports, discovery: 2-4 s here) and walk a little
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 3, err[-2000:]
    report = json.loads(out)
    assert report["error"] == "interrupted" and report["completed"] is False
    assert report["sim_time"] > 0.0
    assert _alive(children) == []
    assert "Traceback" not in err and "FATAL" not in err
