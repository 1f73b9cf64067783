"""``python -m rabbit_msgs_py.quiet_start [--hold] MODULE [ARGS...]``: run a node module as
``python -m MODULE ARGS...`` would, but a SIGINT or SIGTERM that arrives while it is still
importing (3-4 s on a slow machine: MuJoCo, NumPy, rclpy) is noted and ends the process
quietly, with status 128 + the signal's number, once the import is done, instead of a
``KeyboardInterrupt`` traceback. (It is not raised where it arrives: an exception raised
inside a C extension's import comes out as that module's ImportError, a traceback again.)
Once the node's ``main()`` runs, :func:`rabbit_msgs_py.node_runner.run_node` takes the signals
over and stops the node in order; once it returned, the process exits with its status and
ignores a signal that comes later. run_stack starts its node processes through this module,
so Ctrl-C at any moment of its start-up prints no traceback.

``--hold``: once imported, wait for the line ``go`` on standard input before starting the
node; anything else (end of input: the parent decided not to start it) exits 0, a signal
meanwhile exits 128 + its number. run_stack starts its nodes so while it looks for another
stack, and the imports and the look take the same seconds."""

from __future__ import annotations

import importlib
import signal
import sys


def main(argv: list[str] | None = None) -> int:
    """Import the module named in ``argv`` with SIGINT and SIGTERM noted, not raised; exit
    128 + the signal's number if one came; with ``--hold`` wait for ``go``; then call the
    module's ``main()`` with ``sys.argv`` set to the module's own command line."""
    argv = sys.argv[1:] if argv is None else argv
    hold = bool(argv) and argv[0] == "--hold"
    argv = argv[1:] if hold else argv
    if not argv or argv[0].startswith("-"):
        print("usage: python -m rabbit_msgs_py.quiet_start [--hold] MODULE [ARGS...]", file=sys.stderr)
        return 2
    arrived: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: arrived.append(signum))
    module = importlib.import_module(argv[0])
    if arrived:
        return 128 + arrived[0]
    for sig in (signal.SIGINT, signal.SIGTERM):  # no C extension imports from here: end at once, quietly
        signal.signal(sig, _exit_quietly)  # until run_node installs its own
    if hold and sys.stdin.readline().strip() != "go":
        return 0
    sys.argv = [argv[0], *argv[1:]]
    status = module.main()
    for sig in (signal.SIGINT, signal.SIGTERM):  # the node is stopped: a late signal must not raise
        signal.signal(sig, signal.SIG_IGN)  # into what the interpreter's exit frees (rclpy's C++)
    return status


def _exit_quietly(signum: int, _frame) -> None:
    raise SystemExit(128 + signum)


if __name__ == "__main__":
    sys.exit(main())
