"""Bring-up of the whole stack in place of a launch file (used by ``scripts/run_stack.py``,
``scripts/bench_stack.py`` and the tests).

* :class:`StackConfig` says what to run; :mod:`rabbit_policy.experiment.scenario` parses
  the script's ``--speed-schedule "0:0.8,10:1.2"`` and ``--push "t:fx:duration"``.
* :class:`Supervisor` is the experiment node: it publishes ``/cmd_speed`` at the
  scheduled sim times (read from ``/joint_states`` stamps), counts steps (``/hzd/step``),
  watches ``/fallen``, detects a stall (no touchdown for ``stall_after`` s of sim time)
  and measures each segment's mean speed (hip x over the segment's second half, so the
  transient after a speed change is left out). It samples the newest state (best effort,
  depth 1) so it never slows the loop; speed changes therefore fire at the first state it
  sees at or after their time — within a few ms of sim time in lockstep on an idle
  machine, more under load, which is why a run with speed changes repeats only to that
  precision, while a constant-speed lockstep run repeats exactly.
* Pushes are not sent by the supervisor but given to ``sim_node`` as its
  ``push_schedule`` parameter: the simulator applies them at their exact sim times, as
  the fast path does, so a push experiment repeats exactly whatever the load.
* :func:`run_in_process` spins policy, controller, simulator and supervisor on one
  executor; :func:`run_multi_process` starts the three nodes as separate processes
  (``python -m <module> --ros-args ...``, exactly what ``ros2 run`` executes) and runs the
  supervisor here.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Float64, Header
from std_srvs.srv import SetBool

from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.conversions import stamp_to_seconds
from rabbit_msgs_py.runtime import freeze_start_up_objects, init_context, spin_timeout_of

from rabbit_policy.experiment.result import Touchdown, WalkResult, run_summary
from rabbit_policy.experiment.scenario import Push, Scenario, format_pushes, validate_schedule
from rabbit_policy.runtime.policies import controller_name
from rabbit_sim.model import ModelOptions
from rabbit_sim.simulation import StopRules

NODE_MODULES = {
    "policy_node": "rabbit_policy.policy_node",
    "hzd_controller_node": "rabbit_hzd_controller.hzd_controller_node",
    "sim_node": "rabbit_sim.sim_node",
    "recorder_node": "rabbit_sim.recorder_node",
}


@dataclass(frozen=True)
class StackConfig:
    """One run of the stack. ``schedule``: (start time s, speed m/s) pairs, first at 0.
    ``decision_period``: -1 = the policy's own (classic: every 20 ticks; learned: as
    trained), 0 = once per step, N > 0 = every N ticks, the controller applying each gait at
    once (told so on ``/hzd/gait_timing``). ``markers_rate``: ``/rabbit/markers`` per s of
    sim time (0 = off); ``viewer``: sim_node opens MuJoCo's viewer."""

    duration: float
    schedule: tuple[tuple[float, float], ...]
    controller: str = "classic"
    mode: str = "lockstep"
    rtf: float = 1.0
    model: str = "paper"
    library_mode: str = "interpolate"
    gait_dir: str = ""
    policy_file: str = ""
    decision_period: int = -1
    pushes: tuple[Push, ...] = ()
    push_duration: float = 0.1
    stats_file: str = ""
    record: str = ""
    record_compression: str = "none"
    record_overwrite: bool = False
    record_stats_file: str = ""
    markers_rate: float = 30.0
    viewer: bool = False
    recorder_timeout: float = 10.0  # s (wall): a recorder that made no progress this long fails the run
    rules: StopRules = StopRules()  # the fall and stall rules of every experiment

    def __post_init__(self) -> None:
        if not self.duration > 0.0:
            raise ValueError("duration must be > 0 s")
        object.__setattr__(self, "controller", controller_name(self.controller))
        validate_schedule(self.schedule)
        if not (math.isfinite(self.recorder_timeout) and self.recorder_timeout > 0.0):
            raise ValueError(f"recorder_timeout must be a finite number > 0 s, got {self.recorder_timeout}")
        if not (math.isfinite(self.rtf) and self.rtf > 0.0):
            raise ValueError(f"rtf must be a finite number > 0, got {self.rtf}")
        if not (isinstance(self.decision_period, int) and self.decision_period >= -1):
            raise ValueError(f"decision_period must be -1 (the policy's own), 0 or a whole number of ticks, "
                             f"got {self.decision_period!r}")

    def node_parameters(self) -> dict[str, dict[str, object]]:
        """The ROS parameters of each node for this run (the recorder only if recording)."""
        params: dict[str, dict[str, object]] = {
            "policy_node": {
                "policy": self.controller,
                "library_mode": self.library_mode,
                "gait_dir": self.gait_dir,
                "policy_file": self.policy_file,
                "initial_speed": self.schedule[0][1],
                "decision_period": self.decision_period,
            },
            "hzd_controller_node": {},
            "sim_node": {
                "model": self.model,
                "mode": self.mode,
                "rtf": self.rtf,
                "stop_time": self.duration,
                "push_duration": self.push_duration,
                "push_schedule": format_pushes(self.pushes),
                "start_paused": True,
                "wait_for_recorder": bool(self.record) and self.mode in ("lockstep", "paced"),
                "stats_file": self.stats_file,
                "markers_rate": self.markers_rate,
                "viewer": self.viewer,
            },
        }
        if self.record:
            params["recorder_node"] = {
                "output": self.record,
                "compression": self.record_compression,
                "overwrite": self.record_overwrite,
                "stats_file": self.record_stats_file,
            }
        return params


@dataclass
class RunReport:
    """What a run of the stack did. ``result``: the walk as the fast path reports one (a
    :class:`~rabbit_policy.experiment.result.WalkResult` built from the states and touchdowns
    the supervisor saw), so ``run_stack.py --json`` and ``walk.py --json`` are the same
    report (:func:`~rabbit_policy.experiment.result.run_summary`). ``stalled``: no touchdown
    for ``StackConfig.rules.stall_after`` s, the rule of every experiment."""

    controller: str
    policy: str | None
    result: WalkResult
    wall_time: float
    completed: bool = True
    error: str | None = None
    rejected: int | None = None  # gaits the controller rejected (None: not known, its process is apart)

    fell = property(lambda self: self.result.fell)
    fall_time = property(lambda self: self.result.fall_time)
    stalled = property(lambda self: self.result.stalled)
    stall_time = property(lambda self: self.result.stall_time)
    steps = property(lambda self: self.result.steps)
    sim_time = property(lambda self: self.result.end_time)

    @property
    def segments(self) -> list[dict]:
        """Per schedule segment: ``command``, ``start``, ``end``, ``mean_speed`` (second half;
        None unless the run reached its end), ``reach_time``."""
        return self.result.segments()

    @property
    def rtf(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("nan")

    def summary(self) -> dict[str, object]:
        return {**run_summary(self.controller, self.policy, self.result, self.wall_time, self.completed, self.error),
                "rejected": self.rejected}


class Supervisor(Node):
    """Runs the experiment: speed schedule, segment statistics, falls and stalls, end of run."""

    def __init__(self, config: StackConfig, context=None) -> None:
        super().__init__("run_stack_supervisor", context=context)
        self.config = config
        self._changes = list(config.schedule[1:])  # (t, v) still to command
        self._times: list[float] = []  # every distinct state's sim time (s) and hip x (m)
        self._xs: list[float] = []
        self._start: tuple[float, float] | None = None  # the placed state (t, x)
        self._pending_step: float | None = None  # a touchdown stamp whose next state has not come yet
        self._touchdown_times: list[float] = []
        self.peak_torque = 0.0
        self.fell = False
        self.fall_time: float | None = None
        self.stalled = False
        self.stall_time: float | None = None
        self._last_step_time = 0.0
        self.sim_time = 0.0
        self.first_state_wall: float | None = None
        self.last_state_wall: float | None = None
        self.last_progress_wall: float | None = None  # when sim time last moved (re-sent states do not count)
        self._speed_pub = self.create_publisher(Float64, topics.CMD_SPEED, qos.COMMAND_QOS)
        self.create_subscription(JointState, topics.JOINT_STATES, self._on_state, qos.MONITOR_QOS)
        self.create_subscription(Bool, topics.FALLEN, self._on_fallen, qos.STATUS_QOS)
        self.create_subscription(Header, topics.STEP, self._count_step, qos.EVENT_QOS)
        self._pause_client = self.create_client(SetBool, topics.PAUSE_SERVICE)
        self.recorded_until = -1.0  # s, sim time of the newest state the recorder has written
        if config.record:
            self.create_subscription(Clock, topics.RECORDED_UNTIL, self._on_recorded, qos.STATUS_QOS)

    def _on_recorded(self, msg: Clock) -> None:
        self.recorded_until = stamp_to_seconds(msg.clock)

    @property
    def recording_complete(self) -> bool:
        """The recorder has written the last state this node saw (always true unrecorded)."""
        return not self.config.record or self.recorded_until >= self.sim_time - 1e-9

    def connected(self) -> bool:
        """True once simulator, controller and policy are all visible to this node."""
        return (
            self._pause_client.service_is_ready()
            and self.count_publishers(topics.JOINT_STATES) > 0
            and self.count_publishers(topics.JOINT_TORQUES) > 0
            and self.count_publishers(topics.ALPHA) > 0
            and self.count_subscribers(topics.CMD_SPEED) > 0
            # sim_node and, when recording, the recorder take the torques
            and self.count_subscribers(topics.JOINT_TORQUES) >= (2 if self.config.record else 1)
        )

    @property
    def steps(self) -> int:
        return len(self._touchdown_times)

    def request_start(self):
        """Send the first commanded speed (so a recording holds the whole command history)
        and ask the (paused) simulator to run; returns the service future."""
        self._speed_pub.publish(Float64(data=self.config.schedule[0][1]))
        return self._pause_client.call_async(SetBool.Request(data=False))

    @property
    def done(self) -> bool:
        return self.fell or self.stalled or self.sim_time >= self.config.duration - 1e-9

    def _count_step(self, msg: Header) -> None:
        t = stamp_to_seconds(msg.stamp)  # the sim time of the state on which the stance switched
        self._touchdown_times.append(t)
        if t < self.sim_time:  # the state after it is here already: the touchdown's time (see result())
            self._last_step_time = max(self._last_step_time, self._times[int(np.searchsorted(self._times, t + 1e-9))])
        else:
            self._pending_step = t

    def _on_fallen(self, msg: Bool) -> None:
        if msg.data and not self.fell:
            self.fell = True
            self.fall_time = self.sim_time

    def _on_state(self, msg: JointState) -> None:
        now = time.perf_counter()
        if self.first_state_wall is None:
            self.first_state_wall = now
        self.last_state_wall = now
        t = stamp_to_seconds(msg.header.stamp)
        x = msg.position[0]
        if t != self.sim_time or self.last_progress_wall is None:
            self.last_progress_wall = now
        self.sim_time = t
        if self._start is None:
            self._start = (t, x)
        elif t > (self._times[-1] if self._times else self._start[0]):  # a state sent again is one state
            self._times.append(t)
            self._xs.append(x)
            self.peak_torque = max(self.peak_torque, *(abs(e) for e in msg.effort[3:]))
        if self._pending_step is not None and t > self._pending_step:
            self._last_step_time, self._pending_step = t, None
        if not self.stalled and self.config.rules.stalled(t, self._last_step_time):
            self.stalled, self.stall_time = True, t
            self.get_logger().warning(f"t = {t:.2f} s: no touchdown for {self.config.rules.stall_after} s, stalled")
        while self._changes and t >= self._changes[0][0] - 1e-9:  # the schedule, as ClosedLoop steps it
            _, speed = self._changes.pop(0)
            self._speed_pub.publish(Float64(data=speed))
            self.get_logger().info(f"t = {t:.2f} s: commanding {speed:.2f} m/s")

    def result(self) -> WalkResult:
        """The walk so far, as the fast path reports one. A touchdown is dated as
        :class:`~rabbit_policy.experiment.loop.ClosedLoop` dates it: the state after the
        tick on which the stance switched (the ``/hzd/step`` stamp is the state before it),
        with that state's hip x; the foot's x is on no topic (NaN)."""
        config = self.config
        scenario = Scenario(schedule=config.schedule, pushes=config.pushes, model=ModelOptions(config.model),
                            rules=config.rules)
        t0, x0 = self._start or (0.0, 0.0)
        times, xs = np.array(self._times), np.array(self._xs)
        touchdowns = []
        for stamp in sorted(self._touchdown_times):
            i = int(np.searchsorted(times, stamp + 1e-9, side="right"))  # the first state after it
            if i < len(times):  # (a switch on the last state: that tick was never simulated)
                touchdowns.append(Touchdown(float(times[i]), float("nan"), float(xs[i])))
        return WalkResult(scenario=scenario, fell=self.fell, fall_time=self.fall_time, stalled=self.stalled,
                          stall_time=self.stall_time, start_time=t0, start_x=x0, times=times, hip_x=xs,
                          touchdowns=touchdowns, peak_torque=self.peak_torque, planned_duration=config.duration)

    def report(self, error: str | None = None, policy: str | None = None) -> RunReport:
        wall = (
            self.last_state_wall - self.first_state_wall
            if self.first_state_wall is not None and self.last_state_wall is not None
            else 0.0
        )
        return RunReport(controller=self.config.controller, policy=policy, result=self.result(), wall_time=wall,
                         completed=self.done and error is None, error=error)


STACK_NODE_NAMES = ("sim_node", "hzd_controller_node", "policy_node", "recorder_node", "run_stack_supervisor")


def other_stack(wait: float = 3.0) -> list[str]:
    """Nodes of another rabbit-hzd stack visible in this ROS domain (after ``wait`` s of
    discovery; found ones end the wait early; 1.5 s missed a running stack once on a loaded
    machine), or publishers of its topics; empty if none. Two stacks in one domain
    cross-talk (one's /cmd_speed moves the other), so a launch refuses to start beside one."""
    import rclpy

    context = init_context()
    try:
        node = rclpy.create_node("run_stack_probe", context=context)
        deadline = time.monotonic() + wait
        found: list[str] = []
        while time.monotonic() < deadline and not found:
            time.sleep(0.1)
            found = sorted({name for name in node.get_node_names() if name in STACK_NODE_NAMES})
            for topic in (topics.JOINT_STATES, topics.JOINT_TORQUES, topics.ALPHA):
                if node.count_publishers(topic):
                    found.append(f"a publisher of {topic}")
        node.destroy_node()
        return found
    finally:
        rclpy.shutdown(context=context)


def ros_arguments(parameters: dict[str, object]) -> list[str]:
    """``{"mode": "lockstep", "stop_time": 5.0}`` ->
    ``["--ros-args", "-p", "mode:=lockstep", "-p", "stop_time:=5.0"]``; empty strings are
    left out (the node's default applies)."""
    args = ["--ros-args"]
    for name, value in parameters.items():
        if value == "":
            continue
        text = str(value).lower() if isinstance(value, bool) else repr(value) if isinstance(value, float) else str(value)
        args += ["-p", f"{name}:={text}"]
    return args


REALTIME_HALT_TIMEOUT = 3.0
"""s (wall): a realtime simulation whose time stood still this long after it started
stepping has halted (before the first torque it holds t = 0, however long that takes)."""


def policy_name(config: StackConfig) -> str | None:
    """The name of the policy policy_node runs for ``config`` (as the fast path names it);
    None if it cannot be built here (policy_node then said why)."""
    from rabbit_policy.runtime.policies import PolicyUnavailable, make_policy

    try:
        return make_policy(config.controller, config.gait_dir or None, config.library_mode, config.policy_file or None,
                           decision_period=None if config.decision_period == -1 else config.decision_period).name
    except (PolicyUnavailable, ValueError, OSError):
        return None


def _spin_until_done(executor, supervisor: Supervisor, stall_timeout: float, alive=lambda: None,
                     spin_timeout: float = 0.05, stop=lambda: False) -> str | None:
    """Start the (paused) simulation once every node is connected, then spin until the run
    is over; returns an error message or None. ``stop()`` true (a signal arrived) ends
    the run as "interrupted"; ``alive()`` returns a message when a node process died.
    Progress is sim time moving: a state sent again does not count."""
    from rclpy.executors import ExternalShutdownException

    start = time.perf_counter()
    started = None
    while not supervisor.done:
        running = started is not None and started.done()
        try:
            executor.spin_once(timeout_sec=spin_timeout if running else 0.02)
        except (KeyboardInterrupt, ExternalShutdownException):
            return "interrupted"
        problem = "interrupted" if stop() else alive()
        if problem:
            return problem
        if started is None and supervisor.connected():
            started = supervisor.request_start()
        if not running and time.perf_counter() - start > stall_timeout:
            return f"the nodes did not connect within {stall_timeout:.0f} s"
        if running:
            waited = time.perf_counter() - (supervisor.last_progress_wall or start)
            if supervisor.config.record and waited > supervisor.config.recorder_timeout \
                    and supervisor.recorded_until < supervisor.sim_time - 1e-9:
                return (f"the recorder stopped: it has written up to t = {supervisor.recorded_until:.3f} s and the "
                        f"simulation has waited for it at t = {supervisor.sim_time:.3f} s for {waited:.0f} s")
            if supervisor.config.mode == "realtime" and supervisor.sim_time > 0.0 and waited > REALTIME_HALT_TIMEOUT:
                return (f"the simulation halted at t = {supervisor.sim_time:.3f} s: realtime mode halts when the "
                        "control loop falls behind the wall clock (sim_node's log says why); --mode paced runs "
                        "slower instead")
            if waited > stall_timeout:
                return f"no simulation progress for {stall_timeout:.0f} s (at t = {supervisor.sim_time:.3f} s)"
    return None


def _wait_for_recording(executor, supervisor: Supervisor, timeout: float, alive=lambda: None) -> str | None:
    """After the run: spin until the recorder has written the last state (a node stopped
    earlier could take states still in flight with it); an error message if it does not
    within ``timeout`` s."""
    deadline = time.perf_counter() + timeout
    while not supervisor.recording_complete:
        executor.spin_once(timeout_sec=0.02)
        if alive() or time.perf_counter() > deadline:
            return (f"the recorder did not write the last state (t = {supervisor.sim_time:.3f} s) within "
                    f"{timeout:.0f} s; it has up to t = {supervisor.recorded_until:.3f} s")
    return None


def run_in_process(config: StackConfig, stall_timeout: float = 30.0, executor_kind: str | None = None,
                   observers: Sequence[object] = (), stop=lambda: False) -> tuple[RunReport, dict[str, object]]:
    """Run the stack in this process on one executor; returns the report and the nodes
    (for tests and benchmarks). ``observers``: extra node factories ``f(context)``;
    ``stop()``: polled, true ends the run early (the caller's signal handling)."""
    import rclpy

    from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
    from rabbit_msgs_py.runtime import make_executor
    from rabbit_sim.sim_node import SimNode

    from rabbit_policy.policy_node import PolicyNode

    context = init_context()
    nodes: dict[str, object] = {}
    executor = None
    try:
        params = config.node_parameters()
        nodes["policy_node"] = PolicyNode(context=context, **params["policy_node"])
        nodes["hzd_controller_node"] = HZDControllerNode(context=context, **params["hzd_controller_node"])
        nodes["sim_node"] = SimNode(context=context, **params["sim_node"])
        if "recorder_node" in params:
            from rabbit_sim.recorder_node import RecorderNode

            nodes["recorder_node"] = RecorderNode(context=context, **params["recorder_node"])
        supervisor = nodes["supervisor"] = Supervisor(config, context=context)
        for i, factory in enumerate(observers):
            nodes[f"observer_{i}"] = factory(context)
        executor = make_executor(context, executor_kind)
        for node in nodes.values():
            executor.add_node(node)
        freeze_start_up_objects()
        spin_timeout = min(spin_timeout_of(node) for node in nodes.values())
        error = _spin_until_done(executor, supervisor, stall_timeout, spin_timeout=spin_timeout, stop=stop)
        error = error or _wait_for_recording(executor, supervisor, stall_timeout)
        drain_until = time.monotonic() + 0.3  # deliver what is in flight (last states, recorder)
        while time.monotonic() < drain_until:
            executor.spin_once(timeout_sec=0.005)
        recorder = nodes.get("recorder_node")
        if recorder is not None:
            recorder.close()  # finish the bag now: a failure to is the run's failure
            if recorder.error and not error:
                error = f"recording failed: {recorder.error}"
        policy, controller = nodes.get("policy_node"), nodes.get("hzd_controller_node")
        report = supervisor.report(error, policy.policy.name if policy is not None else None)
        report.rejected = controller.rejected_gaits if controller is not None else None
        return report, nodes
    finally:
        if executor is not None:
            executor.shutdown()  # an executor left alive keeps its wait thread busy
        for node in nodes.values():
            close = getattr(node, "close", None)
            if close:
                close()
            node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)


class NodeProcesses:
    """The three nodes as child processes, each in its own session so that Ctrl-C at the
    terminal reaches only run_stack, which then stops them in order (SIGINT, then SIGTERM,
    then SIGKILL)."""

    def __init__(self, config: StackConfig, log=sys.stderr) -> None:
        self.procs: dict[str, subprocess.Popen] = {}
        env = dict(os.environ)
        for name, params in config.node_parameters().items():
            cmd = [sys.executable, "-m", NODE_MODULES[name], *ros_arguments(params)]
            self.procs[name] = subprocess.Popen(cmd, env=env, stdout=log, stderr=log, start_new_session=True)

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
                      stop=lambda: False) -> RunReport:
    """Start the nodes as processes, supervise the run here, stop them; returns the report.
    ``stop()``: polled, true ends the run early."""
    import rclpy

    from rabbit_msgs_py.runtime import make_executor

    with tempfile.TemporaryDirectory(prefix="rabbit_run_") as scratch:
        if config.record and not config.record_stats_file:  # where the recorder says how it ended
            config = replace(config, record_stats_file=os.path.join(scratch, "recorder.json"))
        context = init_context()
        procs = NodeProcesses(config, log=log)
        supervisor = Supervisor(config, context=context)
        error = None
        try:
            executor = make_executor(context)
            executor.add_node(supervisor)
            error = _spin_until_done(executor, supervisor, stall_timeout, alive=procs.dead, stop=stop)
            error = error or _wait_for_recording(executor, supervisor, stall_timeout, alive=procs.dead)
        finally:
            codes = procs.stop()
            supervisor.destroy_node()
            if context.ok():
                rclpy.shutdown(context=context)
        if config.record:  # a failed recording is the cause whatever else it led to
            error = recording_error(codes.get("recorder_node", 0), config.record_stats_file) or error
        return supervisor.report(error, policy_name(config))


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
