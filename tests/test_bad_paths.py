"""Every command that writes refuses an output it cannot write with one line and exit status 2,
before any work (issue 73): a directory under a regular file cannot be made."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.unit


@pytest.mark.parametrize("command", [
    ["evaluate.py", "--quick", "--out"],
    ["reproduce.py", "--preset", "tiny", "--out"],
    ["train.py", "--algo", "es", "--out"],
    ["train_sb3.py", "--out"],
    ["run_stack.py", "--duration", "1", "--record"],
    ["bench_soak.py", "--duration", "1", "--record"],
], ids=lambda c: c[0])
def test_an_unwritable_output_is_one_line_and_exit_2_before_any_work(tmp_path, command):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    run = subprocess.run([sys.executable, str(ROOT / "scripts" / command[0]), *command[1:], str(blocker / "out")],
                         capture_output=True, text=True, timeout=120, cwd=tmp_path)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1, run.stderr
    assert "cannot write there" in lines[0] and str(blocker / "out") in lines[0]
