"""Running a node as its own process: the body of every node's ``main()`` (needs rclpy).

``ros2 run <pkg> <node>``, the console scripts and ``python -m`` all end up here, so the
executor choice, discovery default and shutdown behaviour are the same everywhere.

Executor: rclpy's experimental ``EventsExecutor`` by default, for the 1 kHz state->torque
round trip (why and how much faster: docs/architecture.md, "Executors");
``RABBIT_EXECUTOR=single`` selects the ``SingleThreadedExecutor`` instead. Nodes spin with
``spin_once(timeout_sec=0.1)`` until a signal asks them to stop: in rclpy 7.1
``EventsExecutor.spin()`` and ``spin_until_future_complete`` without a timeout busy-loop at
100 % CPU and ignore shutdown.
"""

from __future__ import annotations

import functools
import gc
import os
import signal
import time
from typing import Callable, Sequence

from .environment import ensure_localhost_discovery

EXECUTOR_VARIABLE = "RABBIT_EXECUTOR"


def make_executor(context, kind: str | None = None):
    """``EventsExecutor`` (``kind='events'``, the default) or ``SingleThreadedExecutor``
    (``'single'``) bound to ``context``; ``kind`` defaults to ``$RABBIT_EXECUTOR``."""
    kind = (kind or os.environ.get(EXECUTOR_VARIABLE) or "events").lower()
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    if kind == "single":
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor(context=context)
    raise ValueError(f"{EXECUTOR_VARIABLE} must be 'events' or 'single', got {kind!r}")


DEFAULT_SPIN_TIMEOUT = 0.1


def spin_timeout_of(node: object) -> float:
    """How long one ``spin_once`` may wait for ``node`` (s): its ``spin_timeout`` attribute,
    else 0.1 s. A node with a thread of its own that must run on time (the realtime
    simulator's physics thread) asks for a short one: the waiting executor delays the other
    thread (docs/benchmarks.md measures it)."""
    return float(getattr(node, "spin_timeout", DEFAULT_SPIN_TIMEOUT))


def freeze_start_up_objects() -> None:
    """Move every object alive now (modules, nodes, models: what start-up built) out of the
    garbage collector's scans (``gc.freeze``), so that a collection while the loop runs
    walks only what the run allocates. Measured here: without it, a full collection during
    an in-process realtime run could stall the executor for several ms, after which the
    stack answered every state 5-18 ms late for the rest of the run (97 % late ticks); with
    it, 0.06-0.3 % over five runs."""
    gc.collect()
    gc.freeze()


def init_context():
    """A new, initialised rclpy context with the discovery default in force (set here, where
    a process starts using ROS, not when a module is imported)."""
    ensure_localhost_discovery()
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    return context


def run_node(factory: Callable[..., object], args: Sequence[str] | None = None) -> int:
    """Initialise rclpy with ``args`` (``--ros-args ...`` included), build the node with
    ``factory(context=...)``, spin it until SIGINT (Ctrl-C) or SIGTERM, then clean up.

    rclpy's own signal handlers are turned off: they shut the context down under a running
    callback (whose next publish then fails). Here a signal only sets a flag; the callback
    in progress finishes, then the node is closed and destroyed in order. The handlers that
    were there before come back only once every rclpy object of the run is freed: a handler
    that raises (quiet_start's), run while a C++ destructor calls back into Python, aborts
    the process ("terminate called ... SystemExit").
    Returns the process exit status (0, or 1 if the node could not be built or reports
    ``failed``)."""
    ensure_localhost_discovery()
    stop: list[bool] = []
    previous = {sig: signal.signal(sig, lambda *_: stop.append(True)) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _serve(factory, args, stop)
    finally:
        gc.unfreeze()  # freeze_start_up_objects kept the node out of the collector's reach
        gc.collect()  # the run's objects (cycles included) freed while a signal only sets `stop`
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _serve(factory: Callable[..., object], args: Sequence[str] | None, stop: list[bool]) -> int:
    """run_node's body: init, build, spin until ``stop`` holds an entry, close, destroy,
    shut down. Its locals (node, executor, context) are freed when it returns."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    try:
        rclpy.init(args=args, context=context, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # noqa: BLE001 - rclpy raises RCLError for a broken params file or bad --ros-args
        print(f"error: {one_line(str(exc))}", flush=True)
        return 1
    node = executor = None
    status = 0
    try:
        node = factory(context=context)
        executor = make_executor(context)
        executor.add_node(node)
        freeze_start_up_objects()
        timeout = spin_timeout_of(node)
        while not stop and context.ok() and not getattr(node, "done", False):
            executor.spin_once(timeout_sec=timeout)
        drain(executor, node, context)
    except NodeStartError as exc:
        print(f"error: {exc}", flush=True)
        status = 1
    finally:
        if node is not None:
            close = getattr(node, "close", None)
            if close is not None:
                close()
            if getattr(node, "failed", False):  # the node could not do its job (a recording that failed)
                status = 1
            if executor is not None:
                executor.remove_node(node)
            node.destroy_node()
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if context.ok():
            rclpy.shutdown(context=context)
    return status


DRAIN_QUIET = 0.3
"""s: a draining node is done once it did nothing new for this long."""


def drain(executor, node, context) -> None:
    """A node that must not lose what is queued (the recorder) spins on after a stop signal
    until its ``activity()`` count (messages handled) stood still for :data:`DRAIN_QUIET`
    s, at most ``drain_on_exit`` s: a loaded machine gets the time it needs, an idle one
    stops at once. Its ``begin_stop()``, if it has one, is called first."""
    limit = float(getattr(node, "drain_on_exit", 0.0))
    begin_stop = getattr(node, "begin_stop", None)
    if limit > 0.0 and begin_stop is not None:
        begin_stop()
    activity = getattr(node, "activity", None)
    start = time.monotonic()
    last, quiet_since = (activity() if activity else None), start
    while context.ok() and time.monotonic() - start < limit:
        executor.spin_once(timeout_sec=0.01)
        now = time.monotonic()
        if activity is not None:
            current = activity()
            if current != last:
                last, quiet_since = current, now
            elif now - quiet_since > DRAIN_QUIET:
                break


def one_line(text: str, limit: int = 300) -> str:
    """The first line of ``text``, cut to ``limit`` characters (error messages for a log)."""
    first = text.strip().splitlines()[0] if text.strip() else ""
    return first if len(first) <= limit else first[: limit - 3] + "..."


class NodeStartError(RuntimeError):
    """A node cannot start with the parameters it was given (bad value, missing file)."""


def destroyed_if_start_fails(init: Callable) -> Callable:
    """Decorate a node class's ``__init__``: if it raises after ``Node.__init__`` ran, the node
    destroys itself before the error propagates, so it leaves the ROS graph at once. Otherwise
    the half-built node lives on, visible to every process in the domain, until the garbage
    collector frees it (one kept alive by a test's traceback made the next ``run_stack.py`` in
    that domain refuse to start beside "another stack")."""

    @functools.wraps(init)
    def start(self, *args, **kwargs) -> None:
        try:
            init(self, *args, **kwargs)
        except BaseException:
            if hasattr(self, "_type_description_service"):  # the last thing Node.__init__ builds
                self.destroy_node()
            raise

    return start
