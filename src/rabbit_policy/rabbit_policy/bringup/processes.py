"""A run with the nodes as child processes (``python -m <module> --ros-args ...``, what
``ros2 run`` executes), supervised from this process; in the ``composed`` layout (the
default) the simulator and the 1 kHz controller run in this process beside the supervisor,
on its executor, as a component container runs nodes, and only the policy (and a recorder)
are processes of their own."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable

from rabbit_msgs_py.pairing import write_key_file
from rabbit_msgs_py.node_runner import freeze_start_up_objects, init_context, make_executor, spin_timeout_of

from .config import COMPOSED_NODES, NODE_MODULES, StackConfig, policy_name, ros_arguments
from .cpu import CpuMeter
from .in_process import close_nodes, compose
from .probe import AnotherStack
from .supervisor import RunReport, Supervisor, spin_until_done, wait_for_recording


def _prepare_child() -> None:
    """In a node's process before it starts: SIGINT ignored until the process handles it
    itself (:mod:`rabbit_msgs_py.quiet_start`, then run_node), so a stop that comes while
    the interpreter starts prints no "Fatal Python error" (a stop ignored there is followed
    by SIGTERM, which ends it quietly); and (Linux) SIGTERM when run_stack's thread that
    started it ends, so a run_stack killed outright (SIGKILL, a test's timeout) leaves no
    stack running in the domain."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal_on_parent_death(signal.SIGTERM)


def signal_on_parent_death(sig: int) -> None:
    """In a child process before it starts (``preexec_fn``): on Linux, have the kernel send it
    ``sig`` when the thread of the parent that started it ends (``PR_SET_PDEATHSIG``), so that
    a parent killed outright leaves no child running; elsewhere nothing."""
    import ctypes

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, sig)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class NodeProcesses:
    """The three nodes as child processes, each in its own session so that Ctrl-C at the
    terminal reaches only run_stack, which then stops them in order (SIGINT, then SIGTERM,
    then SIGKILL); a run_stack killed outright takes them with it (SIGTERM). Each starts
    through :mod:`rabbit_msgs_py.quiet_start`: stopped while still importing, it exits
    without a traceback."""

    def __init__(self, config: StackConfig, log=sys.stderr, hold: bool = False, skip: tuple[str, ...] = (),
                 key_file: str = "") -> None:
        """``skip``: nodes not to start (they run elsewhere: composed in run_stack's process).
        ``key_file``: where the stack's pairing key is written for them (owner-only, in a
        directory of run_stack's; required when a started node takes a key): each gets the
        file's path, never the key, on its command line."""
        self.procs: dict[str, subprocess.Popen] = {}
        env = dict(os.environ)
        written = False
        for name, params in config.node_parameters().items():
            if name in skip:
                continue
            if params.get("pairing_key"):
                if not key_file:
                    raise ValueError("a node process takes the stack's pairing key: give key_file")
                if not written:
                    write_key_file(Path(key_file), config.pairing_key)
                    written = True
                params = {**{k: v for k, v in params.items() if k != "pairing_key"}, "pairing_key_file": key_file}
            cmd = [sys.executable, "-m", "rabbit_msgs_py.quiet_start", *(["--hold"] if hold else []),
                   NODE_MODULES[name], *ros_arguments(params, config.namespace)]
            self.procs[name] = subprocess.Popen(cmd, env=env, stdout=log, stderr=log, start_new_session=True,
                                                preexec_fn=_prepare_child,
                                                stdin=subprocess.PIPE if hold else subprocess.DEVNULL)

    def release(self) -> None:
        """Held processes (``hold``): start their nodes now (they may still be importing)."""
        for proc in self.procs.values():
            if proc.stdin is not None and proc.poll() is None:
                try:
                    proc.stdin.write(b"go\n")
                    proc.stdin.close()
                except BrokenPipeError:  # it died meanwhile: dead() says so
                    pass

    def dead(self) -> str | None:
        for name, proc in self.procs.items():
            if proc.poll() is not None:
                return f"{name} exited early with status {proc.returncode}"
        return None

    def stop(self, timeout: float = 5.0) -> dict[str, int]:
        """SIGINT, then SIGTERM, then SIGKILL, ``timeout`` s apart (each with SIGCONT: a
        stopped process handles a signal only once it runs); exit statuses by node."""
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            alive = [p for p in self.procs.values() if p.poll() is None]
            if not alive:
                break
            for proc in alive:
                proc.send_signal(sig)
                if sig != signal.SIGKILL:
                    proc.send_signal(signal.SIGCONT)
            deadline = time.monotonic() + timeout
            for proc in alive:
                try:
                    proc.wait(max(0.0, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    pass
        return {name: proc.wait() for name, proc in self.procs.items()}


def run_multi_process(config: StackConfig, stall_timeout: float = 30.0, log=sys.stderr,
                      stop=lambda: False, policy: str | None = None,
                      probe: Callable[[], list[str]] | None = None) -> RunReport:
    """Start the nodes as processes, supervise the run here, stop them; returns the report.
    ``stop()``: polled, true ends the run early; ``policy``: its name for the report (built
    from ``config`` here if not given). ``probe()``: what of another stack runs here
    (:func:`~.probe.other_stack`), asked while the node processes import, held
    (:mod:`rabbit_msgs_py.quiet_start`); if it finds any, they are stopped unstarted and
    :class:`~.probe.AnotherStack` is raised."""
    import rclpy

    if config.layout not in ("composed", "separate"):
        raise ValueError(f"run_multi_process runs the composed or separate layout, not {config.layout}")
    composed = COMPOSED_NODES if config.layout == "composed" else ()
    with tempfile.TemporaryDirectory(prefix="rabbit_run_") as scratch:
        if config.record and not config.record_stats_file:  # where the recorder says how it ended
            config = replace(config, record_stats_file=os.path.join(scratch, "recorder.json"))
        if not config.controller_stats_file:  # where the controller counts the gaits it rejected
            config = replace(config, controller_stats_file=os.path.join(scratch, "controller.json"))
        procs = NodeProcesses(config, log=log, hold=probe is not None, skip=composed,
                              key_file=os.path.join(scratch, "pairing_key"))  # scratch: 0700, removed at exit
        if probe is not None:
            try:
                found = probe()
            except BaseException:
                procs.stop()
                raise
            if found:
                procs.stop()
                raise AnotherStack(found)
            procs.release()
        context = init_context()
        nodes: dict[str, object] = {}
        error = None
        executor = None
        meter = CpuMeter({**{name: proc.pid for name, proc in procs.procs.items()},
                          ("run_stack" if not composed else "+".join(("run_stack",) + composed)): os.getpid()})
        cpu = None
        try:
            compose(config, context, composed, nodes)
            supervisor = nodes["supervisor"] = Supervisor(config, context=context)
            executor = make_executor(context)
            for node in nodes.values():
                executor.add_node(node)
            if composed:
                freeze_start_up_objects()
            error = spin_until_done(executor, supervisor, stall_timeout, alive=procs.dead, stop=stop,
                                    spin_timeout=min(0.05, *(spin_timeout_of(n) for n in nodes.values())),
                                    meter=meter)
            error = error or wait_for_recording(executor, supervisor, stall_timeout, alive=procs.dead)
            cpu = meter.per_tick_us(supervisor.sim_stamp)
        finally:
            if executor is not None:
                executor.shutdown()
            codes = procs.stop()
            close_nodes(nodes)
            if context.ok():
                rclpy.shutdown(context=context)
        if config.record:  # a failed recording is the cause whatever else it led to
            error = recording_error(codes.get("recorder_node", 0), config.record_stats_file) or error
        report = supervisor.report(error, policy or policy_name(config))
        report.take_controller_counts(controller_counts(config.controller_stats_file))
        report.cpu_us_per_tick = cpu
        return report


def controller_counts(stats_file: str) -> dict | None:
    """The counts the controller process wrote on close (``HZDControllerNode.statistics``),
    or None if it wrote none (it was killed, or never started)."""
    try:
        counts = json.loads(Path(stats_file).read_text())
    except (OSError, ValueError):
        return None
    return counts if isinstance(counts, dict) else None


def recording_error(exit_status: int, stats_file: str) -> str | None:
    """Why a recording failed (None if it did not): the recorder's own message from its
    stats file, else its exit status."""
    try:
        message = json.loads(Path(stats_file).read_text()).get("error")
    except (OSError, ValueError):
        message = None
    if message:
        return f"recording failed: {message}"
    if exit_status != 0:
        return f"recording failed: recorder_node exited with status {exit_status} (see its log)"
    if not Path(stats_file).is_file():
        return "recording failed: recorder_node did not finish its bag (no stats written)"
    return None
