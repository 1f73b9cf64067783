"""scripts/bench_soak.py runs run_stack as a child process for an hour: a bench_soak killed
outright (SIGKILL, a job's timeout) must not leave that stack walking on in the domain."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
from proc_helpers import children

pytestmark = [pytest.mark.ros, pytest.mark.slow]

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "bench_soak.py"
START_WAIT = 300.0
"""s (wall): how long bench_soak may take to start its walk (its imports and run_stack's on a busy
2-core machine)."""


def _running(pid: str) -> bool:
    """Alive and not a zombie waiting to be reaped."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_a_bench_soak_killed_outright_stops_its_run_stack(tmp_path):
    log = tmp_path / "stack.log"
    soak = subprocess.Popen([sys.executable, str(SCRIPT), "--layout", "in-process", "--controller", "classic",
                             "--duration", "600", "--log", str(log)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    stack: list[str] = []
    try:
        deadline = time.monotonic() + START_WAIT
        while not stack and soak.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
            stack = children(soak.pid, "run_stack")
        assert len(stack) == 1, f"bench_soak started no run_stack in {START_WAIT:.0f} s (exit status {soak.poll()})"
        while "simulation running" not in log.read_text() and _running(stack[0]) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert "simulation running" in log.read_text(), log.read_text()[-3000:]
        soak.kill()
        soak.wait()
        deadline = time.monotonic() + 60
        while _running(stack[0]) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not _running(stack[0]), log.read_text()[-3000:]
    finally:  # nothing of it left in the domain, whatever failed (a stack left walking fails other tests)
        stack += children(soak.pid, "run_stack")
        if soak.poll() is None:
            soak.kill()
            soak.wait()
        for pid in stack:
            if _running(pid):
                subprocess.run(["kill", "-9", pid])
