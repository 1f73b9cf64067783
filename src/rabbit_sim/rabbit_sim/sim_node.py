"""``sim_node``: the RABBIT MuJoCo simulation as a ROS 2 node.

Publishes ``/joint_states`` (7 joints: position, velocity, applied effort), ``/hip_velocity``
and ``/clock`` every 1 ms tick of simulation time, ``/fallen`` when it changes; applies the
four ``/joint_torques``; takes ``/push`` wrenches; serves ``/sim/reset`` and ``/sim/pause``.

Modes (parameter ``mode``):

* ``lockstep`` (default): after publishing the state of tick n the node waits for one
  torque message, applies it for one step and publishes tick n+1. Runs as fast as the
  loop allows and is deterministic: the same stack gives the same trajectory as the
  ROS-free ``ClosedLoop`` (``scripts/walk.py``). If no torque arrives within
  ``resend_timeout`` s (wall) the state is re-sent: a restarted controller picks it up,
  a live one ignores the duplicate (it answers each distinct state once), so exactly one
  reply per state is ever applied. A reset or pause requested while a reply is due takes
  effect when that reply arrives.
* ``realtime``: the physics steps at 1 kHz of wall-clock time, zero-order hold on the
  newest torque, in the thread that spins the node (a 1 ms timer wakes it; the wall clock
  paces it): no second thread, so a tick never waits for the GIL. After a late wake-up it
  catches up by at most two ticks and skips the rest (counted, logged). After start and
  reset the physics holds the initial state (re-publishing it) until the first torque
  arrives. A watchdog applies damping torques ``-damping * joint rate`` when no torque
  arrived for ``watchdog_timeout`` s (8 ms: the gaits go unstable at about 10 ms of
  delay) and says so in the log; it logs again when commands resume. Ticks whose torque
  (the reply to the previous state) had not arrived when the next step was due are late;
  once a second the log says when the loop fell behind (late ticks, worst delay).

The robot starts (and restarts on ``/sim/reset``) in the newest state on
``/sim/initial_state`` (transient local; ``policy_node`` publishes the state at phase 0 of
the gait in force); until one arrives the simulation waits. The simulator knows no gait
and no controller. When the robot falls (the
paper's limits) ``/fallen`` turns true and the physics halts until a reset.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.environment import ensure_localhost_discovery

ensure_localhost_discovery()

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import TwistStamped, Wrench, WrenchStamped  # noqa: E402
from rcl_interfaces.msg import SetParametersResult  # noqa: E402
from rclpy.event_handler import SubscriptionEventCallbacks  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Bool, Float64MultiArray, UInt32, UInt64  # noqa: E402
from std_srvs.srv import SetBool, Trigger  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from rabbit_msgs_py import qos, topics  # noqa: E402
from rabbit_msgs_py.conversions import MessageError, joint_state_vectors, torques_from_msg  # noqa: E402
from rabbit_msgs_py.joints import JOINT_NAMES, N_ACTUATED  # noqa: E402
from rabbit_msgs_py.parameters import Param, coerce, declare, finite  # noqa: E402
from rabbit_msgs_py.pushes import Push, parse_pushes  # noqa: E402
from rabbit_msgs_py.runtime import NodeStartError, run_node  # noqa: E402

from .marker_msgs import MarkerArrayBuilder  # noqa: E402
from .markers import RobotShapes, marker_period_ticks  # noqa: E402
from .model import load_model  # noqa: E402
from .viewer import PassiveViewer, ViewerUnavailable  # noqa: E402
from .simulation import Simulator  # noqa: E402
from .stepping import (  # noqa: E402
    Lockstep, RealtimeClock, RecorderGate, Reply, SourceProbe, TickStatistics, Verdict, Watchdog, WatchdogEvent)

MODES = ("lockstep", "realtime")
RECORDER_LAG = 4
"""Lockstep with wait_for_recorder: states the recorder may lag behind (its subscriptions
keep 10: with at most 4 outstanding none is ever overwritten)."""
PROBE_WINDOW = 0.3
"""s: lockstep with two publishers on /joint_torques counts the replies to one state this long."""
REPLY_GRACE = 0.0006
"""s: a realtime tick whose reply is still on its way waits this long for it (the reply's
callback then runs the tick) before stepping on the previous torque."""


@dataclass(frozen=True)
class SimSettings:
    """sim_node parameters (see the README's parameter table).

    model: ``paper`` or ``drives`` (see :func:`rabbit_sim.model.load_model`).
    mode: ``lockstep`` or ``realtime``.
    push_duration: how long a ``/push`` wrench is held (s, sim time).
    push_schedule: scripted pushes the simulator applies itself at exact sim times,
        ``"T:FX:DUR,..."`` (s, N, s; :mod:`rabbit_msgs_py.pushes`), again after a reset;
        ``/push`` messages act when they arrive, these do not depend on message timing.
    max_push_force: larger pushes (N, each component) are rejected.
    stop_time: pause the physics at this sim time (s); 0 = run until stopped.
    resend_timeout: lockstep, wall s without a torque before the state is re-sent.
    watchdog_timeout: realtime, wall s without a torque before damping takes over.
    damping: realtime watchdog damping gain (N m s/rad).
    start_paused: start with the physics paused (``/sim/pause`` false starts it); the
        launch script uses it to start the run once every node is connected.
    wait_for_recorder: lockstep, hold the next state while the recorder is more than
        :data:`RECORDER_LAG` states behind (the launch script sets it when recording).
    stats_file: write :meth:`SimNode.statistics` as JSON to this path when the node
        closes ('' = don't); the benchmarks read it.
    markers_rate: ``/rabbit/markers`` messages per second of sim time (0 = none); one also
        goes out whenever RABBIT is placed (start, reset).
    viewer: open MuJoCo's viewer (passive, synced to the simulation at most 60 times per
        wall second); the node does not start without a display.
    """

    model: str = "paper"
    mode: str = "lockstep"
    push_duration: float = 0.1
    push_schedule: str = ""
    max_push_force: float = 2000.0
    stop_time: float = 0.0
    resend_timeout: float = 0.2
    watchdog_timeout: float = 0.008
    damping: float = 20.0
    start_paused: bool = False
    wait_for_recorder: bool = False
    stats_file: str = ""
    markers_rate: float = 30.0
    viewer: bool = False

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise NodeStartError(f"mode must be one of {MODES}, got {self.mode!r}")
        for name in ("push_duration", "max_push_force", "resend_timeout", "watchdog_timeout"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise NodeStartError(f"{name} must be a finite number > 0, got {value}")
        for name in ("stop_time", "damping", "markers_rate"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise NodeStartError(f"{name} must be a finite number >= 0, got {value}")
        if self.stats_file and not Path(self.stats_file).resolve().parent.is_dir():
            raise NodeStartError(f"stats_file {self.stats_file}: its directory does not exist")
        try:
            pushes = parse_pushes(self.push_schedule)
        except ValueError as exc:
            raise NodeStartError(f"push_schedule: {exc}") from None
        if any(abs(p.force_x) > self.max_push_force for p in pushes):
            raise NodeStartError(f"push_schedule: forces must be within +-{self.max_push_force} N")

    @property
    def pushes(self) -> tuple[Push, ...]:
        """``push_schedule`` parsed, by time."""
        return parse_pushes(self.push_schedule)


SIM_PARAMS = {
    "model": Param("paper", "model variant: paper (ideal joints) or drives (RABBIT's gears and joint friction)"),
    "mode": Param("lockstep", "lockstep (one state, one torque reply; deterministic) or realtime (1 kHz wall clock)"),
    "push_duration": Param(0.1, "how long a /push wrench is held, s of sim time, > 0", dynamic=True),
    "push_schedule": Param("", "pushes applied at sim times, 'T:FX:DUR,...' (s, N, s); '' = none"),
    "max_push_force": Param(2000.0, "larger push components are rejected, N, > 0"),
    "stop_time": Param(0.0, "halt the physics at this sim time, s, >= 0 (0 = never)"),
    "resend_timeout": Param(0.2, "lockstep: wall s without a torque before the state is re-sent, > 0"),
    "watchdog_timeout": Param(0.008, "realtime: wall s without a torque before damping takes over, > 0 "
                                     "(the gaits go unstable at about 10 ms of torque delay)"),
    "damping": Param(20.0, "realtime watchdog damping gain, N m s/rad, >= 0"),
    "start_paused": Param(False, "start with the physics paused (/sim/pause false runs it)"),
    "wait_for_recorder": Param(False, "lockstep: publish the next state only while the recorder (/recorder/progress) "
                                      "is at most a few states behind, so a recording loses nothing under any load"),
    "stats_file": Param("", "write the run statistics as JSON here when the node closes ('' = don't)"),
    "markers_rate": Param(30.0, "/rabbit/markers (RViz/Foxglove 3D view) per s of sim time, >= 0 (0 = off)"),
    "viewer": Param(False, "open MuJoCo's own viewer window (passive, synced to the simulation; needs a display)"),
}


def stamp_of(seconds: float) -> Time:
    """Sim time (s) -> builtin_interfaces/Time, rounded to the nanosecond."""
    ns = int(round(seconds * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


class SimNode(Node):
    """The simulator node. All physics runs under ``self._lock``."""

    def __init__(self, context=None, **overrides) -> None:
        super().__init__("sim_node", context=context)
        values = declare(self, SIM_PARAMS, overrides)
        try:
            self.settings = SimSettings(**values)
            self.sim = Simulator(load_model(self.settings.model))
        except (ValueError, TypeError) as exc:
            raise NodeStartError(f"sim_node: {exc}") from exc

        self._lock = threading.RLock()
        self._initial_state: tuple[list[float], list[float]] | None = None
        self._started = False
        self._paused = self.settings.start_paused
        self._halted = False  # fell or reached stop_time
        self._fallen = False
        self.sim.schedule_pushes(self.settings.pushes)  # the Simulator applies them, as on the fast path
        self.pushes_rejected = 0
        self.stats = TickStatistics()  # counters: read by tests, run_stack and the benchmarks
        self.lockstep = Lockstep(self.settings.resend_timeout)
        self.watchdog = Watchdog(self.settings.watchdog_timeout, self.settings.damping)
        self._latest_torques = [0.0] * N_ACTUATED  # realtime: zero-order hold on the newest torque
        self._latest_torque_wall = -1.0

        self._joint_msg = JointState(name=list(JOINT_NAMES))
        self._hip_msg = TwistStamped()
        self._hip_msg.header.frame_id = "world"
        self._state_pub = self.create_publisher(JointState, topics.JOINT_STATES, qos.STREAM_QOS)
        self._hip_pub = self.create_publisher(TwistStamped, topics.HIP_VELOCITY, qos.HIP_VELOCITY_QOS)
        self._clock_pub = self.create_publisher(Clock, topics.CLOCK, qos.CLOCK_QOS)
        self._fallen_pub = self.create_publisher(Bool, topics.FALLEN, qos.STATUS_QOS)
        self._resets_pub = self.create_publisher(UInt32, topics.RESETS, qos.STATUS_QOS)
        self.placements = 0  # start + resets, published on /sim/resets
        self._push_applied_pub = self.create_publisher(WrenchStamped, topics.PUSH_APPLIED, qos.EVENT_QOS)
        self._controllers = 0  # publishers matched on /joint_torques
        self.probe = SourceProbe(PROBE_WINDOW)  # lockstep, two of them: replies counted, not applied
        self._answer_again_pub = self.create_publisher(UInt32, topics.ANSWER_AGAIN, qos.STATUS_QOS)
        self._answer_again = 0
        self._answer_again_pub.publish(UInt32(data=0))  # the count in force: a controller that starts now sees 0
        self._shapes = RobotShapes(self.sim.model)
        self._marker_builder = MarkerArrayBuilder()
        self._marker_period = marker_period_ticks(self.settings.markers_rate, self.sim.timestep)
        self._markers_pub = self.create_publisher(MarkerArray, topics.MARKERS, qos.MARKERS_QOS)
        self.viewer = None
        if self.settings.viewer:
            try:
                self.viewer = PassiveViewer(self.sim.model, self.sim.data)
            except ViewerUnavailable as exc:
                raise NodeStartError(f"sim_node: {exc}") from None
        self.create_subscription(Float64MultiArray, topics.JOINT_TORQUES, self._on_torques, qos.STREAM_QOS,
                                 event_callbacks=SubscriptionEventCallbacks(matched=self._on_torque_sources))
        self.create_subscription(JointState, topics.INITIAL_STATE, self._on_initial_state, qos.GAIT_QOS)
        self.create_subscription(Wrench, topics.PUSH, self._on_push, qos.COMMAND_QOS)
        self.recorder = RecorderGate(self.settings.wait_for_recorder, RECORDER_LAG)
        if self.settings.wait_for_recorder:
            self.create_subscription(UInt64, topics.RECORDER_PROGRESS, self._on_recorder_progress, qos.STREAM_QOS)
        self.create_service(Trigger, topics.RESET_SERVICE, self._on_reset)
        self.create_service(SetBool, topics.PAUSE_SERVICE, self._on_pause)
        self._fallen_pub.publish(Bool(data=False))
        self.add_on_set_parameters_callback(self._on_set_parameters)

        # realtime: the physics steps in the thread that spins this node, woken by a 1 ms
        # timer and paced by the wall clock (RealtimeClock): no second thread, so a tick
        # never waits for the GIL; executors spinning it wait at most 1 ms
        self.spin_timeout = 0.1 if self.settings.mode == "lockstep" else 0.001
        self.clock = RealtimeClock(self.sim.timestep)
        self._held_ticks = 0
        self._late_window = (0, 0, 0, time.perf_counter())  # ticks, late, skipped, start of the window
        if self.settings.mode == "lockstep":
            self.create_timer(0.05, self._lockstep_supervise)
        else:
            self.create_timer(self.sim.timestep, self._realtime_wake)
        self.get_logger().info(
            f"RABBIT simulation ({self.settings.model} model, {self.settings.mode} mode) waiting for a state on "
            f"{topics.INITIAL_STATE}"
        )

    # ----------------------------------------------------------------- status
    @property
    def fallen(self) -> bool:
        return self._fallen

    @property
    def halted(self) -> bool:
        return self._halted

    @property
    def time(self) -> float:
        """Simulation time (s)."""
        return self.sim.time

    # counters, for tests and scripts
    ticks = property(lambda self: self.stats.ticks)
    states_published = property(lambda self: self.stats.states_published)
    torques_received = property(lambda self: self.stats.torques_received)
    torques_rejected = property(lambda self: self.stats.torques_rejected)
    damped_ticks = property(lambda self: self.watchdog.damped_ticks)
    resends = property(lambda self: self.lockstep.resends)

    def close(self) -> None:
        """Close the viewer and write the statistics file; called before the node is destroyed."""
        if self.viewer is not None:
            self.viewer.close()
            self.viewer = None
        if self.settings.stats_file:
            try:
                Path(self.settings.stats_file).write_text(strict_json.dumps(self.statistics()) + "\n")
            except OSError as exc:
                self.get_logger().error(f"cannot write stats_file {self.settings.stats_file}: {exc}")

    # -------------------------------------------------------------- callbacks
    def _on_set_parameters(self, parameters: list) -> SetParametersResult:
        """Only ``push_duration`` may change at run time (``ros2 param set``)."""
        for param in parameters:
            if param.name != "push_duration":
                return SetParametersResult(successful=False, reason=f"{param.name} is fixed at start-up")
            try:
                value = finite("push_duration", coerce(param.name, param.value, 0.0), low=1e-9)
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=f"{exc} (s)")
            self.settings = replace(self.settings, push_duration=value)
        return SetParametersResult(successful=True)

    def _on_initial_state(self, msg: JointState) -> None:
        try:
            state = joint_state_vectors(msg.name, msg.position, msg.velocity)
        except MessageError as exc:
            self.get_logger().error(f"ignoring malformed {topics.INITIAL_STATE}: {exc}")
            return
        with self._lock:
            self._initial_state = state
            if not self._started:
                self._place()
                self.get_logger().info(
                    f"robot placed in the initial state (hip at {state[1][0]:.2f} m/s); simulation "
                    + ("paused" if self._paused else "running")
                )

    def _on_torques(self, msg: Float64MultiArray) -> None:
        now = time.perf_counter()
        try:
            torques = torques_from_msg(msg)
        except MessageError as exc:
            self.stats.torques_rejected += 1
            self.get_logger().error(f"ignoring malformed {topics.JOINT_TORQUES}: {exc}", throttle_duration_sec=1.0)
            return
        with self._lock:
            self.stats.torque_received(now)
            if self.settings.mode == "realtime":
                self._latest_torques = torques
                self._latest_torque_wall = now
                if self._started and not (self._paused or self._halted) and self.clock.overdue() >= 0.0:
                    self._run_due_ticks()  # the tick waited for this reply
                return
            if self.probe.active:
                self.stats.torques_rejected += 1
                self.probe.reply(torques)
                return  # whose? lockstep applies no torque until one controller is known
            reply = self.lockstep.on_reply(torques, self._paused or self.recorder.missed_start())
            if reply is Reply.RESET:
                self._place()
                self.get_logger().info("robot back in the initial state at t = 0 s")
            elif reply is Reply.STEP:
                self._advance(torques)
            # IGNORE: unsolicited (a second controller?), the supervisor timer warns; HOLD: kept until unpaused

    def _on_torque_sources(self, status) -> None:
        """Publishers on /joint_torques matched or gone (a QoS event, immediate). Lockstep
        with more than one: apply no reply and probe — ask for the due state to be answered
        again and count the replies (:meth:`_probe_verdict`). A controller that died may
        still count as matched for a while (until its lease expires), so the count alone
        does not stop the loop; two replies to one state do."""
        with self._lock:
            self._controllers = status.current_count
            if self.settings.mode != "lockstep":
                return
            if self._controllers > 1 and not self.probe.active:
                self._start_probe()
            elif self._controllers <= 1 and self.probe.active:
                self.probe.active = False
                self.get_logger().info(f"one publisher on {topics.JOINT_TORQUES} again: the physics goes on")
                self._ask_again()

    def _ask_again(self) -> None:
        """Ask the controller(s) to answer the due state again, and re-send it."""
        self._answer_again += 1
        self._answer_again_pub.publish(UInt32(data=self._answer_again))
        if self._started and self.lockstep.awaiting_reply:
            self._publish_state()

    def _start_probe(self) -> None:
        self.probe.start()
        self._ask_again()

    def _probe_verdict(self) -> None:
        """One reply to the state asked again: go on with it; none: wait as usual; two or
        more: two live sources, stay stopped, say so, probe again."""
        verdict = self.probe.verdict()
        if verdict is Verdict.MANY:
            self.get_logger().error(
                f"{self._controllers} publishers on {topics.JOINT_TORQUES} and {self.probe.replies} replies to one "
                f"state: lockstep applies torques from exactly one controller; the physics waits at "
                f"t = {self.sim.time:.3f} s until only one is left", throttle_duration_sec=5.0)
            self._start_probe()
        elif verdict is Verdict.ONE:
            torques = self.probe.torques
            if self.lockstep.on_reply(torques, self._paused or self.recorder.missed_start()) is Reply.STEP:
                self._advance(torques)

    def _on_push(self, msg: Wrench) -> None:
        values = (msg.force.x, msg.force.z, msg.torque.y)
        bad = [v for v in values if not (abs(v) <= self.settings.max_push_force)]
        if bad:
            self.get_logger().error(
                f"ignoring push {values}: components must be finite and within +-{self.settings.max_push_force} N"
            )
            self.pushes_rejected += 1
            return
        if msg.force.y or msg.torque.x or msg.torque.z:
            self.get_logger().warning("push: the model is planar; force.y, torque.x and torque.z are ignored")
        with self._lock:
            self.sim.push(msg.force.x, self.settings.push_duration, msg.force.z, msg.torque.y)
            self._publish_push_applied()
            self.get_logger().info(
                f"push at t = {self.sim.time:.3f} s: fx = {msg.force.x:.1f} N, fz = {msg.force.z:.1f} N, "
                f"ty = {msg.torque.y:.1f} N m for {self.settings.push_duration:.3f} s"
            )

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self._lock:
            if self._initial_state is None:
                response.success = False
                response.message = f"no initial state received on {topics.INITIAL_STATE} yet"
                return response
            if self.lockstep.request_reset():
                # the reply to the state in flight is still due: reset when it arrives
                response.success = True
                response.message = "reset at the next tick"
                return response
            self._place()
        response.success = True
        response.message = "robot back in the initial state at t = 0 s"
        self.get_logger().info(response.message)
        return response

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        with self._lock:
            self._paused = bool(request.data)
            if not self._paused and self.settings.mode == "lockstep":
                held = None if self.recorder.missed_start() else self.lockstep.take_held()
                if held is not None:
                    self._advance(held)
                elif self.lockstep.awaiting_reply:
                    self._publish_state()  # the reply is still due: a controller that came late gets the state
        response.success = True
        response.message = "paused" if request.data else "running"
        self.get_logger().info(f"simulation {response.message} at t = {self.sim.time:.3f} s")
        return response

    # ---------------------------------------------------------------- physics
    def _place(self) -> None:
        pushing = any(self.sim.push_wrench)
        self.sim.reset(*self._initial_state)
        self.placements += 1
        self._resets_pub.publish(UInt32(data=self.placements))  # before the placed state goes out
        if pushing:  # the reset removed it
            self._publish_push_applied()
        self._started = True
        self._halted = False
        self.lockstep.restart()
        self.stats.unanswered.clear()
        self._latest_torque_wall = -1.0
        if self._fallen:
            self._fallen = False
            self._fallen_pub.publish(Bool(data=False))
        if self._marker_period:
            self._publish_markers()  # a viewer shows the robot where it stands, before it walks
        if self.viewer is not None:
            self.viewer.sync(force=True)
        if self.settings.mode == "lockstep":
            self._publish_state()
            self.lockstep.published()

    def _advance(self, torques: list[float]) -> None:
        """Lockstep: apply one reply, step, publish the next state (its reply is then due,
        unless the physics halted) — held while a recorder we wait for lags behind."""
        self._step(torques)
        if self.recorder.lags(self.stats.states_published):
            self.recorder.state_held = True
            return
        self._send_next_state()

    def _send_next_state(self) -> None:
        self._publish_state()
        if not self._halted:
            self.lockstep.published()

    def _on_recorder_progress(self, msg: UInt64) -> None:
        with self._lock:
            recorder = self.recorder
            recorder.recorded = msg.data
            if not self._paused and self.lockstep.held_torques is not None and not recorder.missed_start():
                self._advance(self.lockstep.take_held())  # the first state is recorded: go
            elif recorder.state_held and not recorder.lags(self.stats.states_published):
                recorder.state_held = False
                self._send_next_state()

    def _publish_push_applied(self) -> None:
        """``/push_applied``: the push acting from now on (zeros: none)."""
        msg = WrenchStamped()
        msg.header.stamp = stamp_of(self.sim.time)
        msg.header.frame_id = "world"
        msg.wrench.force.x, msg.wrench.force.z, msg.wrench.torque.y = self.sim.push_wrench
        self._push_applied_pub.publish(msg)

    def _publish_markers(self) -> None:
        shapes = self._shapes.shapes(self.sim.data)
        self._markers_pub.publish(self._marker_builder.build(shapes, stamp_of(self.sim.time)))

    def _step(self, torques: list[float]) -> None:
        sim = self.sim
        sim.step(torques)
        self.stats.tick(time.perf_counter())
        if self._marker_period and round(sim.time / sim.timestep) % self._marker_period == 0:
            self._publish_markers()
        if self.viewer is not None:
            self.viewer.sync()
        if sim.push_changed:  # a scheduled push started, or a push ended
            self._publish_push_applied()
            fx, fz, ty = sim.push_wrench
            if fx or fz or ty:
                self.get_logger().info(f"scheduled push at t = {sim.time:.3f} s: fx = {fx:.1f} N")
        if sim.fallen():
            self._halted = True
            self._fallen = True
            self._fallen_pub.publish(Bool(data=True))
            qpos = sim.data.qpos
            self.get_logger().warning(
                f"RABBIT fell at t = {sim.time:.3f} s (hip height {qpos[1]:.3f} m, torso pitch {qpos[2]:.3f} rad); "
                f"physics halted, call {topics.RESET_SERVICE} to start again"
            )
        elif self.settings.stop_time and sim.time >= self.settings.stop_time - 1e-9:
            self._halted = True
            self.get_logger().info(f"stop_time {self.settings.stop_time:.3f} s reached; physics halted")

    def _publish_state(self, track_latency: bool = False) -> None:
        data = self.sim.data
        stamp = stamp_of(data.time)
        msg = self._joint_msg
        msg.header.stamp = stamp
        msg.position = data.qpos.tolist()
        msg.velocity = data.qvel.tolist()
        msg.effort = data.qfrc_actuator.tolist()
        hip = self._hip_msg
        hip.header.stamp = stamp
        hip.twist.linear.x = float(data.qvel[0])
        hip.twist.linear.z = float(data.qvel[1])
        hip.twist.angular.y = float(data.qvel[2])
        self._state_pub.publish(msg)
        self._hip_pub.publish(hip)
        self._clock_pub.publish(Clock(clock=stamp))
        self.stats.state_sent(time.perf_counter(), track_latency)

    def _lockstep_supervise(self) -> None:
        """Wall-clock timer (20 Hz): re-send the state when its reply is overdue."""
        with self._lock:
            if self.probe.active:
                self._probe_verdict()
                return
            if self._started and self.recorder.missed_start():
                self._publish_state()  # again, until the recorder has it (the controller answers a state once)
                self.get_logger().info("lockstep: waiting for the recorder to receive the first state",
                                       throttle_duration_sec=5.0)
                return
            if self.recorder.state_held:
                self.get_logger().warning(
                    f"lockstep: waiting for the recorder ({self.stats.states_published - self.recorder.recorded} "
                    "states behind)",
                    throttle_duration_sec=5.0)
                return
            waited = self.lockstep.resend_due(self._paused)
            if waited is None:
                return
            controllers = self.count_publishers(topics.JOINT_TORQUES)
            why = (f"no node publishes {topics.JOINT_TORQUES}: is hzd_controller_node running?" if controllers == 0
                   else "the controller has not answered: it waits for a gait on "
                        f"{topics.ALPHA} and {topics.KD}, or is busy")
            self.get_logger().warning(
                f"lockstep: no torque for the state at t = {self.sim.time:.3f} s after {waited:.1f} s; "
                f"re-sending it ({why})",
                throttle_duration_sec=5.0,
            )
            self._publish_state()

    def _realtime_wake(self) -> None:
        """Realtime timer (1 ms): run the ticks now due by the wall clock, zero-order hold."""
        with self._lock:
            if not self._started or self._paused or self._halted:
                self.stats.unanswered.clear()
                self.clock.restart()
                return
            if self.stats.unanswered and self.clock.overdue() < REPLY_GRACE:
                return  # the reply is on its way (queued behind this timer): it runs the tick
            self._run_due_ticks()

    def _run_due_ticks(self) -> None:
        """The ticks due now by the wall clock (caller holds the lock)."""
        for _ in range(self.clock.due()):
            if self._latest_torque_wall < 0.0:
                # hold the initial state (re-published every 10 ms) until the controller answers
                self._held_ticks += 1
                if self._held_ticks % 10 == 1:
                    self._publish_state()
                continue
            self._held_ticks = 0
            self._realtime_tick()
            if self._halted:
                break
        self._report_lateness()

    def _report_lateness(self) -> None:
        """Once a second: say in the log when the control loop fell behind in that second
        (more than 5 % late ticks, or skipped ticks), with the worst delay."""
        ticks, late, skipped, since = self._late_window
        now = time.perf_counter()
        if now - since < 1.0:
            return
        new_ticks, new_late = self.stats.ticks - ticks, self.stats.late_ticks - late
        new_skipped = self.clock.skipped - skipped
        if new_ticks and (new_late / new_ticks > 0.05 or new_skipped):
            worst = max(list(self.stats.latencies_ms)[-new_ticks:] or [0.0])
            self.get_logger().warning(
                f"realtime: the control loop fell behind at t = {self.sim.time:.2f} s: {new_late} of {new_ticks} "
                f"ticks late and {new_skipped} skipped in the last second, worst delay {worst:.1f} ms"
            )
        self._late_window = (self.stats.ticks, self.stats.late_ticks, self.clock.skipped, now)

    def _realtime_tick(self) -> None:
        now = time.perf_counter()
        self.stats.realtime_tick_due(now)
        rates = self.sim.data.qvel[3:3 + N_ACTUATED].tolist()
        torques, event = self.watchdog.torques(self._latest_torques, self._latest_torque_wall, now, rates)
        if event is WatchdogEvent.RESUMED:
            self.get_logger().info(f"torque commands resumed at t = {self.sim.time:.3f} s; damping off")
        elif event is WatchdogEvent.TRIPPED:
            self.get_logger().warning(
                f"watchdog: no torque for {self.watchdog.timeout * 1e3:.0f} ms at t = {self.sim.time:.3f} s; "
                f"applying damping ({self.watchdog.damping:.0f} N m s/rad) until commands resume"
            )
        self._step(torques)
        self._publish_state(track_latency=True)

    @property
    def pushes_applied(self) -> int:
        """Pushes started since the node started (scheduled and ``/push``)."""
        return self.sim.pushes_started

    def statistics(self) -> dict:
        """Counters for scripts and benchmarks (JSON-ready: None, never NaN)."""
        return self.stats.summary(self.sim.time, {"damped_ticks": self.damped_ticks, "resends": self.resends,
                                                  "skipped_ticks": self.clock.skipped})


def main(args: list[str] | None = None) -> int:
    """Console script / ``ros2 run rabbit_sim sim_node``."""
    return run_node(SimNode, args)


if __name__ == "__main__":
    sys.exit(main())
