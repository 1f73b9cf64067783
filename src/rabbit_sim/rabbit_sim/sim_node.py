"""``sim_node``: the RABBIT MuJoCo simulation as a ROS 2 node.

Publishes each state (every 1 ms tick of sim time) as :class:`~rabbit_sim.state_topics.StateTopics`
says, ``/fallen`` when it changes, and the URDF of its model once on ``/robot_description``;
applies the four ``/joint_torques`` of the controller it is paired with
(``rabbit_msgs_py.pairing``); takes ``/push`` wrenches; serves ``/sim/reset``, ``/sim/pause``
and ``/sim/release_controller``. The robot starts (and restarts on a reset) in the newest
``/sim/initial_state``; it knows no gait and no controller. How it steps in each ``mode`` is
:class:`rabbit_sim.stepping.SimDriver` (ROS-free): this node hands it its events and carries
out the actions it returns. The modes and their guarantees: docs/architecture.md.
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import fields, replace
from pathlib import Path

from geometry_msgs.msg import Wrench, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Header, String
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import MarkerArray

from rabbit_msgs_py import qos, strict_json, topics
from rabbit_msgs_py.conversions import (
    MessageError, controller_id, joint_state_vectors, stamp_from_ns, stamp_to_ns, torques_from_bytes)
from rabbit_msgs_py.decision_ticks import parse_gait_timing
from rabbit_msgs_py.log_lines import LineLogger
from rabbit_msgs_py.parameters import Param, coerce, declare, finite, forget_secrets
from rabbit_msgs_py.node_runner import NodeStartError, destroyed_if_start_fails, run_node
from rabbit_msgs_py.rejections import RejectionLog, refuse
from rabbit_msgs_py.service_callers import CallerLog
from rabbit_msgs_py.pairing import resolve_key
from rabbit_msgs_py.polled import subscribe_drained
from rabbit_msgs_py.solo import PROCESS_SOLO_CHECK, SoloStart
from rabbit_msgs_py.timers import OneShot, wall_timer

from .marker_msgs import MarkerArrayBuilder
from .physics.model import load_model
from .stepping.settings import RUN_TIME_PARAMS, SECRET_PARAMS, SimSettings
from .physics.simulation import Simulator
from .state_topics import StateTopics
from .stepping import Fallen, Frame, Log, Markers, Placed, PushApplied, SimDriver, State, TorquePublishers
from .urdf import urdf_from_model
from .viewer import PassiveViewer, ViewerUnavailable


SIM_PARAMS = {f.name: Param(f.default, f.metadata["help"], dynamic=f.name in RUN_TIME_PARAMS + SECRET_PARAMS,
                            range=f.metadata.get("range"), step=f.metadata.get("step", 0.0),
                            choices=f.metadata.get("choices"))
              for f in fields(SimSettings)}
"""sim_node's parameters, declared from :class:`SimSettings` (one place for each default)."""


class SimNode(Node):
    """Parameters, topics, services and timers around a :class:`SimDriver` (under ``self._lock``)."""

    @destroyed_if_start_fails
    def __init__(self, context=None, namespace: str | None = None, **overrides) -> None:
        super().__init__("sim_node", context=context, namespace=namespace)
        values = declare(self, SIM_PARAMS, overrides)
        forget_secrets(self, SECRET_PARAMS)
        try:
            self.settings = SimSettings(**values)
            key, self._key_source = resolve_key(self.settings.pairing_key, file=self.settings.pairing_key_file)
            self.driver = SimDriver(self.settings, Simulator(load_model(self.settings.model_options)),
                                    shapes=bool(self.settings.markers_rate), namespace=self.get_namespace(), key=key)
        except (ValueError, TypeError) as exc:
            raise NodeStartError(f"sim_node: {exc}") from exc
        self.sim = self.driver.sim
        self._lock = threading.RLock()
        self._marker_builder = MarkerArrayBuilder()
        self._log = LineLogger(self.get_logger())  # the core's lines: throttled by key
        self._callers = CallerLog(self)  # who called /sim/reset or /sim/pause, in the log
        self.viewer = None
        if self.settings.viewer:
            try:
                self.viewer = PassiveViewer(self.sim.model, self.sim.data)
            except ViewerUnavailable as exc:
                raise NodeStartError(f"sim_node: {exc}") from None
        self._pace_timer = None  # paced: the one-shot wake-up of a state that waits for its wall time
        self._liveliness: tuple[int, int] | None = None  # controllers (alive, lapsed); None: none declares a lease
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.spin_timeout = 0.001 if self.settings.mode == "realtime" else 0.1  # (see the timers in _wire)
        self.solo = SoloStart(self, "simulator", self.settings.solo_check, self._wire,
                              service=topics.RELEASE_CONTROLLER_SERVICE)

    def _wire(self) -> None:
        """Publishers, subscriptions, services and timers: once no other simulator runs in
        this namespace (:class:`~rabbit_msgs_py.solo.SoloStart`)."""
        pub = self.create_publisher
        self.source = controller_id(self.get_name())  # this instance, in its signatures (batches, mode)
        self._states = StateTopics(self, self.settings.batch_ticks, self.settings.clock_ticks,
                                   self.driver.pairing.key, self.source)
        self._fallen_pub = pub(Bool, topics.FALLEN, qos.STATUS_QOS)
        self._push_applied_pub = pub(WrenchStamped, topics.PUSH_APPLIED, qos.EVENT_QOS)
        self._markers_pub = pub(MarkerArray, topics.MARKERS, qos.MARKERS_QOS)
        self.driver.markers_wanted = lambda: self._markers_pub.get_subscription_count() > 0  # none built for nobody
        pub(String, topics.ROBOT_DESCRIPTION, qos.STATUS_QOS).publish(String(data=urdf_from_model(self.sim.model)))
        key, mode = self.driver.pairing.key, self.settings.mode  # signed where keyed: a controller takes no other
        pub(String, topics.SIM_MODE, qos.STATUS_QOS).publish(String(
            data=key.sign_settings(self.source, mode) if key is not None else mode))
        self._torque_topic, self._rejections = self.resolve_topic_name(topics.JOINT_TORQUES), RejectionLog()
        wall_timer(self, 1.0, lambda: [self.get_logger().warning(line) for line in self._rejections.flush()])
        subscribe_drained(self, JointState, topics.JOINT_TORQUES, self._on_torques, qos.STREAM_QOS, raw=True)
        # which controller is alive (stopped or killed vs busy): liveliness events of a raw subscription to its
        # touchdowns (a few a second, not its 1 kHz replies) that matches only publishers declaring a lease
        self.create_subscription(Header, topics.STEP, lambda _raw: None, qos.LIVELINESS_MONITOR_QOS,
                                 raw=True, event_callbacks=SubscriptionEventCallbacks(
                                     liveliness=self._on_liveliness, incompatible_qos=lambda _info: None))
        self.create_subscription(JointState, topics.INITIAL_STATE, self._on_initial_state, qos.GAIT_QOS)
        self.create_subscription(Wrench, topics.PUSH, self._on_push, qos.COMMAND_QOS)
        subscribe_drained(self, String, topics.GAIT_TIMING, self._on_gait_timing, qos.GAIT_READER_QOS)
        if self.driver.by_replies:  # a recorder's progress: followed from its first report
            self.create_subscription(Clock, topics.RECORDED_UNTIL, self._on_recorded, qos.STATUS_QOS)
        self.create_service(Trigger, topics.RESET_SERVICE, self._on_reset, qos_profile=qos.SERVICE_QOS)
        self.create_service(SetBool, topics.PAUSE_SERVICE, self._on_pause, qos_profile=qos.SERVICE_QOS)
        self.create_service(Trigger, topics.RELEASE_CONTROLLER_SERVICE, self._on_release_controller,
                            qos_profile=qos.SERVICE_QOS)
        self._fallen_pub.publish(Bool(data=False))
        # lockstep/paced: a 20 Hz supervisor (re-sends, the recorder), paced also a one-shot wake-up armed only
        # while a state waits for its wall time; realtime: the physics steps in the thread that spins this node,
        # woken by a 1 ms timer and paced by the wall clock: no second thread, so a tick never waits for the GIL
        mode = self.settings.mode
        if self.driver.by_replies:
            wall_timer(self, 0.05, lambda: self._run(self.driver.supervise, self._torque_publishers,
                                                      lambda: self.count_publishers(topics.RECORDED_UNTIL)))
        if mode == "paced":
            self._pace_timer = OneShot(self, lambda: self._run(self.driver.paced_wake))  # armed by _do
        if mode == "realtime":
            wall_timer(self, self.sim.timestep, lambda: self._run(self.driver.realtime_wake))
        self.get_logger().info(f"RABBIT simulation ({self.settings.describe()}) waiting for a state on "
                               f"{self.resolve_topic_name(topics.INITIAL_STATE)}")
        (self.get_logger().info if self.driver.pairing.key else self.get_logger().warning)(f"pairing: {self._key_source}")

    # ----------------------------------------------------------------- status
    fallen = property(lambda self: self.driver.fallen)
    halted = property(lambda self: self.driver.halted)
    time = property(lambda self: self.sim.time, doc="Simulation time (s).")
    controller = property(lambda self: self.driver.controller, doc="Id of the controller whose torques apply.")
    lockstep = property(lambda self: self.driver.lockstep)
    watchdog = property(lambda self: self.driver.watchdog)
    ticks = property(lambda self: self.driver.stats.ticks)
    states_published = property(lambda self: self.driver.stats.states_published)
    torques_received = property(lambda self: self.driver.stats.torques_received)
    torques_rejected = property(lambda self: self.driver.stats.torques_rejected)
    damped_ticks = property(lambda self: self.driver.watchdog.damped_ticks)
    resends = property(lambda self: self.driver.lockstep.resends)
    pushes_rejected = property(lambda self: self.driver.pushes_rejected)
    pushes_applied = property(lambda self: self.sim.pushes_started, doc="Pushes started (scheduled and /push).")
    placements = property(lambda self: self.driver.placements)
    achieved_rtf = property(lambda self: self.driver.achieved_rtf)
    halt_reason = property(lambda self: self.driver.halt_reason)

    def statistics(self) -> dict:
        """Counters for scripts and benchmarks (JSON-ready: None, never NaN)."""
        return self.driver.statistics()

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
            self.settings = self.driver.settings = replace(self.settings, push_duration=value)
        return SetParametersResult(successful=True)

    def _on_initial_state(self, msg: JointState) -> None:
        try:
            qpos, qvel = joint_state_vectors(msg.name, msg.position, msg.velocity)
        except MessageError as exc:
            refuse(self.get_logger(), self._rejections, "initial_state",
                   f"ignoring malformed {self.resolve_topic_name(topics.INITIAL_STATE)}: {exc}")
            return
        self._run(self.driver.on_initial_state, qpos, qvel)

    def _on_gait_timing(self, msg: String) -> None:
        """A policy's decision period (``at_once:N``): each state it decides on ends a batch (keyed: signed only)."""
        try:
            key = self.driver.pairing.key
            _timing, period = parse_gait_timing(key.verify_settings(msg.data)[1] if key is not None else msg.data)
        except ValueError as exc:
            refuse(self.get_logger(), self._rejections, "gait_timing", lambda exc=exc: f"{self.resolve_topic_name(topics.GAIT_TIMING)}: {exc}; "
                   f"batches keep their {self.settings.batch_ticks}-tick grid")
            return
        with self._lock:
            self._states.batcher.follow_decisions(period)

    def _on_torques(self, msg: bytes) -> None:
        """A reply, serialized (taken raw: the 1 kHz path builds no message object)."""
        now = time.perf_counter()
        try:
            stamp, frame_id, torques = torques_from_bytes(msg)
        except MessageError as exc:
            self.driver.on_malformed_torques()
            refuse(self.get_logger(), self._rejections, "joint_torques", f"ignoring malformed {self._torque_topic}: {exc}")
            return
        self._run(self.driver.on_torques, stamp, frame_id, torques, now)

    def _on_push(self, msg: Wrench) -> None:
        self._run(self.driver.on_push, msg.force.x, msg.force.z, msg.torque.y,
                  bool(msg.force.y or msg.torque.x or msg.torque.z))

    def _on_recorded(self, msg: Clock) -> None:
        self._run(self.driver.on_recorded, stamp_to_ns(msg.clock))

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self._callers(topics.RESET_SERVICE, "reset", self.sim.time)
        with self._lock:
            source = self.resolve_topic_name(topics.INITIAL_STATE)
            response.success, response.message, actions = self.driver.on_reset(source)
            self._do(actions)
        return response

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        self._callers(topics.PAUSE_SERVICE, "pause" if request.data else "resume", self.sim.time)
        with self._lock:
            response.message, actions = self.driver.on_pause(bool(request.data))
            self._do(actions)
        response.success = True
        return response

    def _on_liveliness(self, info) -> None:
        self._liveliness = (info.alive_count, info.not_alive_count)

    def _torque_publishers(self) -> TorquePublishers:
        alive, lapsed = self._liveliness if self._liveliness is not None else (None, 0)
        return TorquePublishers(self.count_publishers(topics.JOINT_TORQUES), alive, lapsed)

    def _on_release_controller(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        with self._lock:
            response.success, response.message, actions = self.driver.on_release_controller()
            self._do(actions)
        return response

    # ---------------------------------------------------------------- actions
    def _run(self, event, *args) -> None:
        """Hand an event to the driver and carry out the actions it returns, in order."""
        with self._lock:
            self._do(event(*args))

    def _do(self, actions: list) -> None:
        for action in actions:
            kind = type(action)
            if kind is State:
                self._states.publish(action)
                self.driver.sent(action)
            elif kind is Log:
                self._log(action)
            elif kind is Frame:
                if self.viewer is not None:
                    self.viewer.sync(force=action.force)
            elif kind is PushApplied:
                msg = WrenchStamped()
                msg.header.stamp, msg.header.frame_id = stamp_from_ns(action.stamp), "world"
                msg.wrench.force.x, msg.wrench.force.z, msg.wrench.torque.y = action.wrench
                self._push_applied_pub.publish(msg)
            elif kind is Markers:
                self._markers_pub.publish(self._marker_builder.build(action.shapes, stamp_from_ns(action.stamp)))
            elif kind is Fallen:
                self._fallen_pub.publish(Bool(data=action.value))
            elif kind is Placed:
                self._states.placed(action.count)
        if self.driver.halted or self.driver.paused:
            self._states.send_batch()  # nothing follows soon: the observers get the last states now
        wait = self.driver.pace_wait if self._pace_timer is not None else None
        if wait is not None:  # paced: wake once when the state that waits is due (no 1 kHz timer)
            self._pace_timer.arm(wait)


def main(args: list[str] | None = None) -> int:
    """Console script / ``ros2 run rabbit_sim sim_node``."""
    return run_node(lambda context: SimNode(context=context, solo_check=PROCESS_SOLO_CHECK), args)


if __name__ == "__main__":
    sys.exit(main())
