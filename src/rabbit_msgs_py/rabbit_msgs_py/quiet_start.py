"""``python -m rabbit_msgs_py.quiet_start MODULE [ARGS...]``: run a node module as
``python -m MODULE ARGS...`` would, but a SIGINT or SIGTERM that arrives while it is still
importing (3-4 s on a slow machine: MuJoCo, NumPy, rclpy) is noted and ends the process
quietly, with status 128 + the signal's number, once the import is done, instead of a
``KeyboardInterrupt`` traceback. (It is not raised where it arrives: an exception raised
inside a C extension's import comes out as that module's ImportError, a traceback again.)
Once the node's ``main()`` runs, :func:`rabbit_msgs_py.runtime.run_node` takes the signals
over and stops the node in order. run_stack starts its node processes through this module,
so Ctrl-C at any moment of its start-up prints no traceback."""

from __future__ import annotations

import importlib
import signal
import sys


def main(argv: list[str] | None = None) -> int:
    """Import the module named by ``argv[0]`` with SIGINT and SIGTERM noted, not raised; exit
    128 + the signal's number if one came, else call the module's ``main()`` with
    ``sys.argv`` set to the module's own command line."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0].startswith("-"):
        print("usage: python -m rabbit_msgs_py.quiet_start MODULE [ARGS...]", file=sys.stderr)
        return 2
    arrived: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: arrived.append(signum))  # until run_node installs its own
    module = importlib.import_module(argv[0])
    if arrived:
        return 128 + arrived[0]
    sys.argv = [argv[0], *argv[1:]]
    return module.main()


if __name__ == "__main__":
    sys.exit(main())
