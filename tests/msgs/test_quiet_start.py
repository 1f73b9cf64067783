"""rabbit_msgs_py.quiet_start: a node process stopped while it still imports exits with
128 + the signal's number once the import is done, never starting the node, and prints no
traceback (run_stack starts its nodes through it; a signal raised inside NumPy's import
once came out as an ImportError traceback)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

pytestmark = pytest.mark.ros  # (node processes)

SLOW_MODULE = '''
import sys, time
print("importing", flush=True)
time.sleep(3)

def main():
    print("main ran", flush=True)
    return 0
'''


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_while_the_node_module_imports_exits_quietly(tmp_path, sig):
    (tmp_path / "slow_node_module.py").write_text(SLOW_MODULE)
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    proc = subprocess.Popen([sys.executable, "-m", "rabbit_msgs_py.quiet_start", "slow_node_module"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "importing"  # it is inside the import now
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + sig and "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert "main ran" not in out


def test_a_node_module_runs_with_its_own_command_line(tmp_path):
    (tmp_path / "echo_node_module.py").write_text("import sys\n\ndef main():\n    print(sys.argv[1:])\n    return 4\n")
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    out = subprocess.run([sys.executable, "-m", "rabbit_msgs_py.quiet_start", "echo_node_module", "--ros-args", "-p",
                          "x:=1"], env=env, capture_output=True, text=True, timeout=30)
    assert out.returncode == 4 and out.stdout.strip() == "['--ros-args', '-p', 'x:=1']"
    usage = subprocess.run([sys.executable, "-m", "rabbit_msgs_py.quiet_start"], capture_output=True, text=True,
                           timeout=30)
    assert usage.returncode == 2 and usage.stderr.startswith("usage:")
