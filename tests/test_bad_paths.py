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


@pytest.mark.parametrize("command, checkpoint", [(["train.py", "--algo", "es"], "checkpoint.pt"),
                                                 (["train_sb3.py"], "sb3_checkpoint.zip")],
                         ids=["train.py", "train_sb3.py"])
def test_a_training_refuses_its_run_directory_before_torch_loads(tmp_path, command, checkpoint):
    """An unwritable, a non-empty (without --resume) or a checkpointless (with it) --out is
    refused by the command's first step: torch and the environments, 2-3 s of imports on a
    quiet 2-core machine, are never loaded."""
    from rabbit_policy.commands import train_sb3
    from rabbit_policy.learning import sb3

    assert train_sb3.CHECKPOINT == sb3.CHECKPOINT
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("")
    module = f"rabbit_policy.commands.{command[0][:-3]}"
    cases = {"/proc/x": "cannot write there", str(tmp_path / "full"): "is not empty; use --resume",
             f"{tmp_path / 'new'} --resume": f"--resume: no {tmp_path / 'new' / checkpoint}"}
    for out, message in cases.items():
        argv = [*command[1:], "--out", *out.split()]
        code = (f"import sys; from {module} import main\ntry:\n    main({argv!r})\nexcept SystemExit as e:\n"
                "    print(e.code, 'torch' in sys.modules, 'gymnasium' in sys.modules)")
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        assert run.stdout.split() == ["2", "False", "False"], (out, run.stdout, run.stderr)
        assert run.stderr.count("\n") == 1 and message in run.stderr, run.stderr
