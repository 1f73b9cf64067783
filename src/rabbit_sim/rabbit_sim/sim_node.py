"""``sim_node``: the RABBIT MuJoCo simulation as a ROS 2 node.

Publishes ``/joint_states`` (7 joints: position, velocity, applied effort), ``/hip_velocity``
and ``/clock`` every 1 ms tick of simulation time, ``/fallen`` when it changes; applies the
four ``/joint_torques``; takes ``/push`` wrenches; serves ``/sim/reset`` and ``/sim/pause``.

Modes (parameter ``mode``):

* ``lockstep`` (default): after publishing the state of tick n the node waits for one
  torque reply, applies it for one step and publishes tick n+1. Runs as fast as the
  loop allows and is deterministic: the same stack gives the same trajectory as the
  ROS-free ``ClosedLoop`` (``scripts/walk.py``). A reply is applied only if it carries the
  stamp of the state now due and comes from the controller the node is paired with (the
  first to answer; ``header.frame_id`` of the reply): a rogue publisher, a second
  controller or a late duplicate never moves the robot. Another controller takes over
  only after the paired one has left a state unanswered for 1 s (a restarted controller
  is a new instance). If no reply arrives within ``resend_timeout`` s (wall) the state
  is re-sent; a live controller ignores the duplicate (it answers each distinct state
  once). A reset or pause requested while a reply is due takes effect when it arrives.
* ``paced``: lockstep held back to the wall clock: a state goes out no earlier than its
  sim time divided by ``rtf`` (target real-time factor, default 1.0) after the start.
  The physics never steps without the torque for its state, so the trajectory is
  lockstep's bit for bit; a machine that cannot keep up runs slower (the achieved
  real-time factor is logged every 5 s) and never falls or stalls because of it.
* ``realtime`` (free-running, for latency studies): the physics steps at 1 kHz of wall-clock time, zero-order hold on the
  newest torque, in the thread that spins the node (a 1 ms timer wakes it; the wall clock
  paces it): no second thread, so a tick never waits for the GIL. After a late wake-up it
  catches up by at most two ticks and skips the rest (counted, logged). After start and
  reset the physics holds the initial state (re-publishing it) until the first torque
  arrives. A watchdog applies damping torques ``-damping * joint rate`` when no torque
  arrived for ``watchdog_timeout`` s (8 ms: the gaits go unstable at about 10 ms of
  delay) and says so in the log; it logs again when commands resume. Ticks whose torque
  (the reply to the previous state) had not arrived when the next step was due are late;
  once a second the log says when the loop fell behind (late ticks, worst delay), and
  when more than ``max_late_fraction`` of a second's ticks were late it halts the physics
  with a log line that names the cause, instead of walking on stale torques until
  RABBIT falls (``paced`` is the mode for a slow or busy machine).

The robot starts (and restarts on ``/sim/reset``) in the newest state on
``/sim/initial_state`` (transient local; ``policy_node`` publishes the state at phase 0 of
the gait in force); until one arrives the simulation waits. The simulator knows no gait
and no controller. When the robot falls (the
paper's limits) ``/fallen`` turns true and the physics halts until a reset.
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import fields, replace
from pathlib import Path

from rabbit_msgs_py import strict_json
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TwistStamped, Wrench, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, UInt32
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.conversions import (
    MessageError, joint_state_vectors, short, stamp_to_ns, torques_from_msg)
from rabbit_msgs_py.joints import JOINT_NAMES, N_ACTUATED
from rabbit_msgs_py.parameters import Param, coerce, declare, finite
from rabbit_msgs_py.runtime import NodeStartError, run_node

from .marker_msgs import MarkerArrayBuilder
from .markers import RobotShapes, marker_period_ticks
from .model import load_model
from .viewer import PassiveViewer, ViewerUnavailable
from .simulation import Simulator
from .settings import REPLY_MODES, RUN_TIME_PARAMS, SimSettings
from .stepping import (
    RECORDER_LAG, RECORDER_RESEND, REPLY_GRACE, TAKEOVER_AFTER,
    LatenessMonitor, Lockstep, Pacer, RealtimeClock, RecorderGate, Reply, StreamPairing, TickStatistics, Watchdog,
    WatchdogEvent)

SERVICE_QOS = QoSProfile(depth=1000)
"""Reset and pause requests: a deep queue, so that many callers at once are each served
(with rclpy's default depth 10, requests beyond 10 arriving together were dropped and their
callers waited for ever). Replies share one topic: a caller that makes many calls at once
needs a client depth as deep as the burst to take its own (docs/faults.md)."""


SIM_PARAMS = {f.name: Param(f.default, f.metadata["help"], dynamic=f.name in RUN_TIME_PARAMS)
              for f in fields(SimSettings)}
"""sim_node's parameters, declared from :class:`SimSettings` (one place for each default)."""


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
        mode = self.settings.mode
        self.by_replies = mode in REPLY_MODES

        self._lock = threading.RLock()
        self._initial_state: tuple[list[float], list[float]] | None = None
        self._started = False
        self._paused = self.settings.start_paused
        self._halted = False  # fell, reached stop_time, or (realtime) fell too far behind
        self._fallen = False
        self.sim.schedule_pushes(self.settings.pushes)  # the Simulator applies them, as on the fast path
        self.pushes_rejected = 0
        self.stats = TickStatistics()  # counters: read by tests, run_stack and the benchmarks
        self.lockstep = Lockstep(self.settings.resend_timeout, TAKEOVER_AFTER)
        self.pacer = Pacer(self.settings.rtf) if mode == "paced" else None
        self._pace_pending = False  # paced: the newest state waits for its wall time
        self.pairing = StreamPairing(TAKEOVER_AFTER)  # realtime: torques from one controller
        self.watchdog = Watchdog(self.settings.watchdog_timeout, self.settings.damping)
        self.lateness = LatenessMonitor(self.settings.max_late_fraction)
        self._latest_torques = [0.0] * N_ACTUATED  # realtime: zero-order hold on the newest torque
        self._latest_torque_wall = -1.0
        self._published_stamp: int | None = None  # ns, the newest state published
        self._recorder_resent = 0.0
        self.halt_reason = ""
        self.achieved_rtf: float | None = None  # paced: over the last 5 s

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
        self.create_subscription(JointState, topics.JOINT_TORQUES, self._on_torques, qos.STREAM_QOS)
        self.create_subscription(JointState, topics.INITIAL_STATE, self._on_initial_state, qos.GAIT_QOS)
        self.create_subscription(Wrench, topics.PUSH, self._on_push, qos.COMMAND_QOS)
        self.recorder = RecorderGate(self.settings.wait_for_recorder and self.by_replies, RECORDER_LAG,
                                     round(self.sim.timestep * 1e9))
        if self.recorder.enabled:
            self.create_subscription(Clock, topics.RECORDED_UNTIL, self._on_recorded, qos.STATUS_QOS)
        self.create_service(Trigger, topics.RESET_SERVICE, self._on_reset, qos_profile=SERVICE_QOS)
        self.create_service(SetBool, topics.PAUSE_SERVICE, self._on_pause, qos_profile=SERVICE_QOS)
        self._fallen_pub.publish(Bool(data=False))
        self.add_on_set_parameters_callback(self._on_set_parameters)

        # lockstep/paced: a 20 Hz supervisor (re-sends, takeovers, the recorder), paced also
        # a 1 ms wake-up for states that wait for their wall time; realtime: the physics steps
        # in the thread that spins this node, woken by a 1 ms timer and paced by the wall
        # clock (RealtimeClock): no second thread, so a tick never waits for the GIL
        self.spin_timeout = 0.1 if mode == "lockstep" else 0.001
        self.clock = RealtimeClock(self.sim.timestep)
        self._held_ticks = 0
        if self.by_replies:
            self.create_timer(0.05, self._lockstep_supervise)
        if mode == "paced":
            self.create_timer(self.sim.timestep, self._paced_wake)
        if mode == "realtime":
            self.create_timer(self.sim.timestep, self._realtime_wake)
        self.get_logger().info(
            f"RABBIT simulation ({self.settings.model} model, {mode} mode"
            + (f", rtf {self.settings.rtf:g}" if mode == "paced" else "")
            + f") waiting for a state on {topics.INITIAL_STATE}"
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

    @property
    def controller(self) -> str | None:
        """Id of the controller whose torques are applied (None before the first reply)."""
        return self.lockstep.controller if self.by_replies else self.pairing.controller

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

    def _on_torques(self, msg: JointState) -> None:
        now = time.perf_counter()
        try:
            stamp, source, torques = torques_from_msg(msg)
        except MessageError as exc:
            self.stats.torques_rejected += 1
            self.get_logger().error(f"ignoring malformed {topics.JOINT_TORQUES}: {exc}", throttle_duration_sec=1.0)
            return
        with self._lock:
            self.stats.torque_received(now, stamp)
            if not self.by_replies:
                if not self.pairing.accepts(source, now):
                    self._refuse(source)
                    return
                self._latest_torques = torques
                self._latest_torque_wall = now
                if self._started and not (self._paused or self._halted) and self.clock.overdue() >= 0.0:
                    self._run_due_ticks()  # the tick waited for this reply
                return
            self._act(self.lockstep.on_reply(stamp, source, torques, self._must_hold()), torques, source)

    def _act(self, reply: Reply, torques: list[float], source: str) -> None:
        """Carry out what :class:`Lockstep` made of a reply (caller holds the lock)."""
        if reply is Reply.STEP:
            self._advance(torques)
        elif reply is Reply.RESET:
            self._place()
            self.get_logger().info("robot back in the initial state at t = 0 s")
        elif reply is Reply.FOREIGN:
            self._refuse(source)
        # IGNORE: answers no state now due (a duplicate or stale stamp); HOLD: kept until the step may run

    def _refuse(self, source: str) -> None:
        self.stats.torques_rejected += 1
        self.get_logger().error(
            f"ignoring torques from {source or 'an unnamed publisher'} on {topics.JOINT_TORQUES}: this simulator "
            f"takes them from {self.controller} only (another takes over after {TAKEOVER_AFTER:.0f} s without "
            "an answer from it)", throttle_duration_sec=5.0)

    def _must_hold(self) -> bool:
        """Lockstep/paced: the physics may not step now (paused, or a recorder lags)."""
        return self._paused or self.recorder.holds(self._published_stamp)

    def _on_push(self, msg: Wrench) -> None:
        values = (msg.force.x, msg.force.z, msg.torque.y)
        bad = [v for v in values if not (abs(v) <= self.settings.max_push_force)]
        if bad:
            self.get_logger().error(
                f"ignoring push {short(values)}: components must be finite and within "
                f"+-{self.settings.max_push_force} N"
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
            if not self._paused and self.pacer is not None:
                self.pacer.restart(self.sim.time)  # pace from now: no rush to make up the pause
            if not self._paused and self.by_replies:
                self._resume()
        response.success = True
        response.message = "paused" if request.data else "running"
        self.get_logger().info(f"simulation {response.message} at t = {self.sim.time:.3f} s")
        return response

    def _resume(self) -> None:
        """Lockstep/paced: step on torques held while the step could not run, or send the
        due state again for a controller (or recorder) that came late."""
        if self._must_hold():
            return
        held = self.lockstep.take_held()
        if held is not None:
            self._advance(held)
        elif self.lockstep.awaiting_reply:
            self._publish_state()

    def _on_recorded(self, msg: Clock) -> None:
        with self._lock:
            self.recorder.recorded = stamp_to_ns(msg.clock)
            if not self._paused and self.lockstep.held_torques is not None:
                self._resume()

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
        self.halt_reason = ""
        self._pace_pending = False
        self.lockstep.restart()
        if self.pacer is not None:
            self.pacer.restart(0.0)
        self.stats.forget()
        self._latest_torque_wall = -1.0
        if self._fallen:
            self._fallen = False
            self._fallen_pub.publish(Bool(data=False))
        if self._marker_period:
            self._publish_markers()  # a viewer shows the robot where it stands, before it walks
        if self.viewer is not None:
            self.viewer.sync(force=True)
        if self.by_replies:
            self._send_next_state()

    def _advance(self, torques: list[float]) -> None:
        """Lockstep/paced: apply one reply, step, publish the next state (its reply is then
        due, unless the physics halted); paced, the state waits for its wall time."""
        self._step(torques)
        if self.pacer is not None and not self._halted and self.pacer.wait(self.sim.time) > 0.0:
            self._pace_pending = True  # _paced_wake sends it
            return
        self._send_next_state()

    def _send_next_state(self) -> None:
        stamp = self._publish_state()
        if not self._halted:
            self.lockstep.published(stamp)

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

    def _publish_state(self, track_latency: bool = False) -> int:
        """Publish the state now (joint states, hip velocity, clock); returns its stamp (ns)."""
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
        self._published_stamp = stamp_to_ns(stamp)
        self.stats.state_sent(time.perf_counter(), self._published_stamp, track_latency)
        return self._published_stamp

    def _lockstep_supervise(self) -> None:
        """Wall-clock timer (20 Hz), lockstep and paced: a controller taking over, the
        recorder's first state, and re-sending the state when its reply is overdue."""
        with self._lock:
            if not self._started or self._pace_pending:
                return
            takeover = self.lockstep.takeover(self._must_hold())
            if takeover is not None:
                old, new, reply, torques = takeover
                self.get_logger().warning(f"controller {new} takes over from {old}, which left the state at "
                                          f"t = {self.sim.time:.3f} s unanswered for {TAKEOVER_AFTER:.0f} s")
                self._act(reply, torques, new)
                return
            now = time.perf_counter()
            if not self._paused and self.recorder.holds(self._published_stamp):
                if now - self._recorder_resent >= RECORDER_RESEND:
                    self._recorder_resent = now
                    self._publish_state()  # the recorder may never have had it (connected late)
                self.get_logger().warning(
                    f"lockstep: waiting for the recorder: {self.recorder.behind(self._published_stamp)}",
                    throttle_duration_sec=5.0)
                return
            waited = self.lockstep.resend_due(self._paused)
            if waited is None:
                return
            controllers = self.count_publishers(topics.JOINT_TORQUES)
            why = (f"no node publishes {topics.JOINT_TORQUES}: is hzd_controller_node running?" if controllers == 0
                   else f"controller {self.lockstep.controller or '(none answered yet)'} has not answered: it waits "
                        f"for a gait on {topics.ALPHA} and {topics.KD}, is busy, or died (a killed node stays "
                        "listed for up to 20 s)")
            self.get_logger().warning(
                f"lockstep: no torque for the state at t = {self.sim.time:.3f} s after {waited:.1f} s; "
                f"re-sending it ({why})",
                throttle_duration_sec=5.0,
            )
            self._publish_state()

    def _paced_wake(self) -> None:
        """Paced timer (1 ms): send the state that waits for its wall time; report the
        achieved real-time factor."""
        with self._lock:
            if self._pace_pending and self.pacer.wait(self.sim.time) <= 0.0:
                self._pace_pending = False
                self._send_next_state()
            achieved = self.pacer.achieved(self.sim.time)
            if achieved is not None and self._started and not (self._paused or self._halted):
                self.achieved_rtf = achieved
                self.get_logger().info(
                    f"paced: real-time factor {achieved:.2f} (target {self.settings.rtf:g}) at t = {self.sim.time:.1f} s"
                    + ("; this machine cannot keep up, the simulation runs slower" if achieved < 0.95 * self.settings.rtf
                       else ""))

    def _realtime_wake(self) -> None:
        """Realtime timer (1 ms): run the ticks now due by the wall clock, zero-order hold."""
        with self._lock:
            if not self._started or self._paused or self._halted:
                self.stats.forget()
                self.clock.restart()
                return
            if self.stats.awaiting_reply and self.clock.overdue() < REPLY_GRACE:
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
        """Once a second: say in the log when the control loop fell behind in that second;
        halt the physics when it fell too far behind to go on."""
        late = self.lateness.check(self.stats, self.clock.skipped)
        if late is None:
            return
        what = (f"{late.late} of {late.ticks} ticks ran on a stale torque and {late.skipped} were skipped in the last "
                f"second, worst delay {late.worst_ms:.1f} ms")
        if not late.stop:
            self.get_logger().warning(f"realtime: the control loop fell behind at t = {self.sim.time:.2f} s: {what}")
            return
        self._halted = True
        self.halt_reason = f"the control loop could not keep up with the wall clock ({what})"
        self.get_logger().error(
            f"realtime: physics halted at t = {self.sim.time:.2f} s: {self.halt_reason}; walking on stale torques "
            f"would make RABBIT fall. On a slow or busy machine use mode:=paced (never steps without its torque)")

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
        extra = {"damped_ticks": self.damped_ticks, "resends": self.resends, "skipped_ticks": self.clock.skipped,
                 "halt_reason": self.halt_reason or None}
        if self.pacer is not None:
            wall = self.stats.last_tick_wall - (self.stats.first_tick_wall or 0.0)
            extra["achieved_rtf"] = self.sim.time / wall if self.stats.first_tick_wall is not None and wall > 0 else None
            extra["paced_fell_behind"] = self.pacer.behind_count
        return self.stats.summary(self.sim.time, extra)


def main(args: list[str] | None = None) -> int:
    """Console script / ``ros2 run rabbit_sim sim_node``."""
    return run_node(SimNode, args)


if __name__ == "__main__":
    sys.exit(main())
