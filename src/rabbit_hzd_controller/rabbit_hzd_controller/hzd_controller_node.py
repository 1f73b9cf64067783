"""``hzd_controller_node``: the HZD PD controller as a ROS 2 node (1 kHz, one torque
command per state).

Subscribes ``/joint_states`` and the gait (``/hzd/alpha``, ``/hzd/kd``, transient local, so a
controller started late gets the gait in force); publishes on ``/joint_torques`` one reply
per distinct state (sensor_msgs/JointState: the four ``ACTUATED_JOINTS`` and their torques
in ``effort``, ``header.stamp`` = the stamp of the state answered, ``header.frame_id`` = this
controller instance's id, :attr:`HZDControllerNode.source`, signed with ``pairing_key`` where
the stack gave one: ``rabbit_msgs_py.pairing``), ``/hzd/step`` at each
touchdown and, while anyone subscribes, ``/hzd/phase`` (the gait phase and its rate on each
state answered, before the reply: what a body-state policy reads); with ``reference_rate`` > 0
also ``/hzd/reference`` and ``/hzd/tracking_error`` (the desired outputs and the tracking
error, for tuning Kp and Kd).
The control law is :class:`rabbit_hzd_controller.controller.HZDController`, the same code
the ROS-free loop runs.

* Time is the simulation's: the stamp of each ``/joint_states`` message. A reset is an
  event: a new count on ``/sim/resets`` restarts the controller on the gait in force (stance
  leg read from the state) and makes it answer the next state even if it equals the last
  one answered; the placed state, if it arrived first and was taken for a re-send, is
  answered then. (A stamp older than the last one also restarts it, for simulators that do
  not publish ``/sim/resets``.)
* The first gait received becomes active at once; later ones (alpha and Kd alike) are
  queued to the next touchdown, so the constraints stay continuous within a step. For a
  policy deciding every N ticks (``policy_node`` ``decision_period``, or a learned policy
  trained so) they apply when they arrive instead, alpha blended in from the outputs in
  force (``HZDController.apply_now``: continuous outputs). Which of the two follows
  ``/hzd/gait_timing`` (from the policy node) unless the ``gait_timing`` parameter forces it.
* ``decision_sync`` (lockstep and paced runs; run_stack sets it): when the policy decides
  every N ticks (``/hzd/gait_timing`` = ``at_once:N``), the reply to a state the policy
  decides on (:class:`rabbit_msgs_py.decision_ticks.PeriodicDecisions`) waits until that
  decision's alpha and Kd are in, and they apply to that very state, as in the ROS-free
  loop: the stack then runs the fast path bit for bit. Gaits are taken in the order they
  come, one alpha and one Kd per due state (a rejected one counts). No decision within
  ``decision_timeout`` s (wall): the state is answered with the gait in force, logged, and
  gaits apply on arrival until the policy's next alpha and Kd are in.
* Malformed alpha/Kd (wrong size or layout, NaN/inf, out of bounds, impact equalities
  violated) are rejected with a logged error; the last good gait stays in force.
* A state identical to the last one answered (a lockstep re-send) is not computed twice:
  the reply already sent goes out again, unchanged (the simulator takes one reply per
  state and ignores the rest, so a reply lost on the way cannot stall lockstep). A freshly
  (re)started controller answers it as new, which is how lockstep resumes after a
  controller restart.
"""

from __future__ import annotations

import sys
import time
from collections import deque
from dataclasses import replace

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, Header, String, UInt32

from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.conversions import (
    MessageError,
    alpha_from_msg,
    controller_id,
    joint_state_vectors,
    phase_to_msg,
    short,
    stamp_to_ns,
    torques_to_msg,
)
from rabbit_msgs_py.decision_ticks import TICK_NS, PeriodicDecisions
from rabbit_msgs_py.joints import ACTUATED_JOINTS
from rabbit_msgs_py.parameters import Param, coerce, declare, finite, forget_secrets
from rabbit_msgs_py.pairing import PairingKey
from rabbit_msgs_py.rejections import RejectionLog
from rabbit_msgs_py.runtime import NodeStartError, destroyed_if_start_fails, run_node
from rabbit_msgs_py.solo import PROCESS_SOLO_CHECK, SOLO_CHECK_HELP, SoloStart

from .controller import ControllerConfig, HZDController, Leg, infer_stance, validate_alpha, validate_kd

FOOT_FRAMES = {Leg.LEFT: "left_foot", Leg.RIGHT: "right_foot"}


_DEFAULTS = ControllerConfig()
CONTROLLER_PARAMS = {
    "kp": Param(_DEFAULTS.kp, "proportional gain of the PD law, N m/rad, finite > 0", dynamic=True, range=(0.001, 1e5)),
    "torque_limit": Param(_DEFAULTS.torque_limit, "torque saturation, N m, finite > 0 (RABBIT: 150)",
                          range=(0.001, 1000.0)),
    "touchdown_min_phase": Param(_DEFAULTS.touchdown_min_phase,
                                 "phase the swing foot must pass before a touchdown counts, in (0, 1)",
                                 range=(0.001, 0.999)),
    "max_kd": Param(_DEFAULTS.max_kd, "largest Kd accepted on /hzd/kd, N m s/rad, finite > 0", dynamic=True,
                    range=(0.001, 1e4)),
    "blend_phase": Param(_DEFAULTS.blend_phase, "blend a new gait in over this much phase after a touchdown "
                                                "that brings it, in [0, 1] (0 = off)", dynamic=True,
                         range=(0.0, 1.0)),
    "within_step_blend": Param(_DEFAULTS.within_step_blend, "gait_timing at_once: blend a new gait in over "
                                                            "this much phase, in [0, 1] (0 = at once)", dynamic=True,
                               range=(0.0, 1.0)),
    "within_step_until": Param(_DEFAULTS.within_step_until, "gait_timing at_once: a gait arriving at or after "
                                                            "this phase waits for the next touchdown, in (0, 1]",
                               dynamic=True, range=(0.001, 1.0)),
}

GAIT_TIMINGS = ("next_step", "at_once")
NODE_PARAMS = {
    "gait_timing": Param("policy", "when a new gait applies: policy (as /hzd/gait_timing says; next_step until "
                                   "it does), next_step (queued to the next touchdown) or at_once (blended in "
                                   "within the step)", choices=("policy",) + GAIT_TIMINGS),
    "decision_sync": Param(False, "lockstep/paced: hold the reply to a state the policy decides on (every N ticks, "
                                  "/hzd/gait_timing at_once:N) until that decision's gait is in (the ROS-free loop "
                                  "bit for bit); not for realtime"),
    "decision_timeout": Param(2.0, "decision_sync: wall s to wait for a due decision before answering with the "
                                   "gait in force, finite > 0", range=(0.001, 3600.0)),
    "reference_rate": Param(0.0, "publish /hzd/reference (the desired outputs y_d, dy_d/dt) and "
                                 "/hzd/tracking_error (y - y_d, dy/dt - dy_d/dt) this many times per s of sim time, "
                                 "on the states answered (0 = off; at most 1000, every state)", range=(0.0, 1000.0)),
    "pairing_key": Param("", "sign every torque reply with this key, so that a simulator given the same key applies "
                             "this controller's torques and no other node's (16-64 characters; run_stack makes one "
                             "per stack; read once at start, then removed so ros2 param get cannot read it). '' = "
                             "unsigned replies", dynamic=True),
    "solo_check": Param(0.0, SOLO_CHECK_HELP.format(kind="controller"), range=(0.0, 60.0)),
}
SECRET_PARAMS = ("pairing_key",)
"""Read once at start and then removed (``rabbit_msgs_py.parameters.forget_secrets``)."""


class HZDControllerNode(Node):
    """Parameters: :data:`CONTROLLER_PARAMS` (``kp``, ``max_kd``, ``blend_phase`` and
    ``within_step_blend`` may change at run time; the rest are read-only) and
    :data:`NODE_PARAMS`."""

    @destroyed_if_start_fails
    def __init__(self, context=None, namespace: str | None = None, **overrides) -> None:
        super().__init__("hzd_controller_node", context=context, namespace=namespace)
        values = declare(self, {**CONTROLLER_PARAMS, **NODE_PARAMS}, overrides)
        forget_secrets(self, SECRET_PARAMS)
        self.follow_policy_timing = values.pop("gait_timing") == "policy"
        self.gait_timing = "next_step" if self.follow_policy_timing else self.get_parameter("gait_timing").value
        self.decision_sync = bool(values.pop("decision_sync"))
        try:
            self.decision_timeout = finite("decision_timeout", values.pop("decision_timeout"), 1e-3)
            self.pairing = PairingKey.parse(values.pop("pairing_key"))
            solo_check = finite("solo_check", values.pop("solo_check"), 0.0)
            rate = values.pop("reference_rate")
            self._reference_every = int(round(1e9 / rate)) if rate else 0  # ns of sim time (0: off)
            if self.gait_timing not in GAIT_TIMINGS:
                raise ValueError(f"gait_timing must be policy or one of {GAIT_TIMINGS}, got {self.gait_timing!r}")
            self.config = ControllerConfig(**values)
        except (ValueError, TypeError) as exc:
            raise NodeStartError(f"hzd_controller_node: {exc}") from None
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self.controller: HZDController | None = None
        self._alpha: list[float] | None = None  # last good gait received
        self._kd: float | None = None
        self._last_stamp = -1
        self._last_state: tuple[list[float], list[float]] | None = None
        self._waiting_state: JointState | None = None  # arrived before the gait was complete
        self._resets: int | None = None  # the last count seen on /sim/resets
        self._restart = False  # a reset was announced: restart on the next state
        self._dropped: JointState | None = None  # the last state dropped as a re-send
        self.states_received = 0
        self.torques_published = 0
        self.replies_repeated = 0  # replies sent again for a state sent again
        self.rejected_gaits = 0
        self.rejected_states = 0
        self._rejections = RejectionLog()  # bad input: counted, logged at most once a second per kind
        self.create_timer(1.0, self._flush_rejections)  # wall clock: a burst's tail is said within a second
        # decision_sync: the due states (None: not holding for decisions), the gaits not yet
        # taken (None for a rejected one), the state waiting for its decision
        self._due: PeriodicDecisions | None = None
        self._gaits: dict[str, deque] = {"alpha": deque(), "kd": deque()}
        self._held: tuple[JointState, list[float], list[float], int, float] | None = None
        # decision_sync, following the policy's timing: the first state waits for /hzd/gait_timing
        # as for the gait (a decision due on it would be missed)
        self._timing_unknown = self.decision_sync and self.follow_policy_timing
        self._sync_paused = False  # a decision timed out: gaits apply on arrival until both come again
        self.decisions_waited = 0  # due states answered with their decision
        self.decisions_timed_out = 0

        self.source = controller_id(self.get_name())  # this instance, in every reply's frame_id
        self._torque_msg = torques_to_msg([0.0] * 4, source=self.source)  # names once; effort, stamp per tick
        self.solo = SoloStart(self, "controller", topics.JOINT_TORQUES, solo_check, self._wire)

    def _wire(self) -> None:
        """Publishers, subscriptions and timers: once no other controller runs in this
        namespace (:class:`~rabbit_msgs_py.solo.SoloStart`)."""
        self._torque_pub = self.create_publisher(JointState, topics.JOINT_TORQUES, qos.TORQUE_QOS)
        self._step_pub = self.create_publisher(Header, topics.STEP, qos.EVENT_QOS)
        self._phase_pub = self.create_publisher(JointState, topics.PHASE, qos.STREAM_QOS)
        if self._reference_every:
            self._reference_pub = self.create_publisher(JointState, topics.REFERENCE, qos.STREAM_QOS)
            self._error_pub = self.create_publisher(JointState, topics.TRACKING_ERROR, qos.STREAM_QOS)
        self.create_subscription(JointState, topics.JOINT_STATES, self._on_state, qos.STREAM_QOS)
        self.create_subscription(Float64MultiArray, topics.ALPHA, self._on_alpha, qos.GAIT_QOS)
        self.create_subscription(Float64, topics.KD, self._on_kd, qos.GAIT_QOS)
        self.create_subscription(String, topics.GAIT_TIMING, self._on_gait_timing, qos.GAIT_QOS)
        self.create_subscription(UInt32, topics.RESETS, self._on_resets, qos.STATUS_QOS)
        self.create_timer(0.05, self._check_held)  # wall clock: decision_timeout
        self.get_logger().info(f"HZD controller {self.source} (Kp = {self.config.kp:.0f} N m/rad) waiting for a gait")


    def _flush_rejections(self) -> None:
        for line in self._rejections.flush():
            self.get_logger().warning(line)

    def _on_set_parameters(self, parameters: list) -> SetParametersResult:
        """``kp``, ``max_kd``, ``blend_phase`` at run time, validated as at start (read-only
        ones are refused by rclpy before this is called)."""
        changes = {}
        for param in parameters:
            if param.name not in CONTROLLER_PARAMS:
                if param.name in NODE_PARAMS:  # (pairing_key is removed at start: cannot be set again)
                    return SetParametersResult(successful=False, reason=f"{param.name} is fixed at start-up")
                continue
            try:
                changes[param.name] = coerce(param.name, param.value, CONTROLLER_PARAMS[param.name].default)
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        try:
            config = replace(self.config, **changes)
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self.config = config
        if self.controller is not None:
            self.controller.config = config
        return SetParametersResult(successful=True)

    # --------------------------------------------------------------- gait
    @property
    def gait(self) -> tuple[list[float], float] | None:
        """The last good gait received: (alpha, 24 rad; Kd, N m s/rad), or None before both."""
        if self._alpha is None or self._kd is None:
            return None
        return list(self._alpha), self._kd

    def _on_alpha(self, msg: Float64MultiArray) -> None:
        try:
            alpha = list(validate_alpha(alpha_from_msg(msg), self.config))
        except (MessageError, ValueError) as exc:
            self.rejected_gaits += 1
            line = self._rejections.line("alpha", f"rejected {self.resolve_topic_name(topics.ALPHA)}: "
                                                  f"{short(str(exc), 200)}; keeping the last good gait")
            if line is not None:
                self.get_logger().error(line)
            self._take("alpha", None)
            return
        self._alpha = alpha
        self._take("alpha", alpha)
        self._answer_waiting_state()

    def _on_kd(self, msg: Float64) -> None:
        try:
            kd = validate_kd(msg.data, self.config)
        except ValueError as exc:
            self.rejected_gaits += 1
            line = self._rejections.line("kd", f"rejected {self.resolve_topic_name(topics.KD)}: "
                                               f"{short(str(exc), 200)}; keeping the last good value")
            if line is not None:
                self.get_logger().error(line)
            self._take("kd", None)
            return
        self._kd = kd
        self._take("kd", kd)
        self._answer_waiting_state()

    def _take(self, part: str, value) -> None:
        """A gait part (``alpha`` or ``kd``; None: rejected) that arrived: kept for the next
        due state while holding for decisions, else applied as ``gait_timing`` says (the
        first gait, before any state, becomes the controller's start gait instead)."""
        if self.controller is None:
            return
        if self._syncing:
            self._gaits[part].append(value)
            self._answer_held()
            return
        if self._sync_paused:
            self._gaits[part].append(value)  # counted: sync resumes once alpha and Kd came again
            if self._gaits["alpha"] and self._gaits["kd"]:
                self._sync_paused = False
                self._forget_gaits()
        if value is not None:
            self._apply(part, value, self.gait_timing == "at_once")

    def _apply(self, part: str, value, at_once: bool) -> None:
        if part == "alpha":
            self.controller.apply_now(tuple(value)) if at_once else self.controller.set_alpha(value)
        else:
            self.controller.set_kd(value) if at_once else self.controller.queue_kd(value)

    def _forget_gaits(self) -> None:
        for parts in self._gaits.values():
            parts.clear()

    @property
    def _syncing(self) -> bool:
        """Holding due states for their decision now."""
        return self._due is not None and not self._sync_paused and self.gait_timing == "at_once"

    def _on_gait_timing(self, msg: String) -> None:
        if not self.follow_policy_timing:
            return
        timing, _, period = msg.data.partition(":")
        if timing not in GAIT_TIMINGS or (period and (timing != "at_once" or not period.isdigit() or int(period) < 1)):
            line = self._rejections.line("gait_timing", f"rejected {self.resolve_topic_name(topics.GAIT_TIMING)} "
                                                        f"{short(repr(msg.data), 60)}: not one of {GAIT_TIMINGS}, or "
                                                        f"at_once:N with N >= 1 ticks; keeping {self.gait_timing}")
            if line is not None:
                self.get_logger().error(line)
            return
        if timing != self.gait_timing:
            self.get_logger().info(f"gaits apply {'when they arrive, blended in' if timing == 'at_once' else 'at the next touchdown'}")
        self.gait_timing = timing
        self._timing_unknown = False
        due = PeriodicDecisions(int(period), TICK_NS) if period and self.decision_sync else None
        if due is not None and self._last_stamp >= 0:
            due.join(self._last_stamp)  # mid-run: the policy's clock has followed since the placement
        if (due is None) != (self._due is None) or (due is not None and due.period != self._due.period):
            self._due = due
            self._release_held("the policy's timing changed")
        self._answer_waiting_state()

    def _on_resets(self, msg: UInt32) -> None:
        first = self._resets is None
        if msg.data == self._resets:
            return
        self._resets = msg.data
        if first:
            return  # the count in force when this node started: nothing to restart
        self._restart = True
        self._forget_gaits()
        self._held = None  # the placed state comes next; its answer is due, not this one's
        self._forget_last_state()

    def _forget_last_state(self) -> None:
        """Answer the next state even if it repeats the last one answered; a state dropped
        as a re-send before the event that asked for this is answered now."""
        self._last_stamp, self._last_state = -1, None
        if self._dropped is not None:
            msg_state, self._dropped = self._dropped, None
            self._on_state(msg_state)

    def _answer_waiting_state(self) -> None:
        """Answer the state that arrived before the first complete gait, if any."""
        if self._waiting_state is not None and self._alpha is not None and self._kd is not None \
                and not self._timing_unknown:
            msg, self._waiting_state = self._waiting_state, None
            self._on_state(msg)

    # -------------------------------------------------------------- state
    def _on_state(self, msg: JointState) -> None:
        try:
            q, dq = joint_state_vectors(msg.name, msg.position, msg.velocity)
        except MessageError as exc:
            self.rejected_states += 1
            self.get_logger().error(f"ignoring malformed {self.resolve_topic_name(topics.JOINT_STATES)}: {exc}",
                                    throttle_duration_sec=1.0)
            return
        self.states_received += 1
        stamp = stamp_to_ns(msg.header.stamp)
        if self._held is not None and stamp == self._held[3]:
            return  # re-sent while it waits for its decision: answered once it is in
        if stamp == self._last_stamp and (q, dq) == self._last_state:
            self._dropped = msg
            self._torque_pub.publish(self._torque_msg)  # a re-send: the same reply again
            self.replies_repeated += 1
            return
        if self._alpha is None or self._kd is None or self._timing_unknown:
            self._waiting_state = msg
            missing = [topics.ALPHA, topics.KD] + ([topics.GAIT_TIMING] if self._timing_unknown else [])
            self.get_logger().warning(
                f"no gait yet (waiting for {' and '.join(self.resolve_topic_name(t) for t in missing)}); the state will "
                "be answered once it is complete",
                throttle_duration_sec=2.0,
            )
            return
        controller = self.controller
        if controller is None or self._restart or stamp < self._last_stamp:
            stance = infer_stance(q, self.config.geometry)
            if controller is None:
                controller = self.controller = HZDController(self._alpha, self._kd, self.config, stance)
                if self._due is not None and stamp > 0:
                    # joined mid-run (the stack restarted this controller): the gait in force is the
                    # policy's newest decision (transient local); a decision on this state went to the
                    # old instance, so it is answered at once instead of waiting out decision_timeout
                    self._due.join(stamp)
            else:
                controller.reset(self._alpha, self._kd, stance)
                self.get_logger().info("simulation reset: controller restarted on the gait")
            self._restart = False
        self._dropped = None
        if self._due is not None and self._due.due(stamp) and self._syncing:
            # (a newer state while one waits: its reply was given up, the older one is dropped)
            self._held = (msg, q, dq, stamp, time.monotonic())
            self._answer_held()
            return
        self._answer(msg, q, dq, stamp)

    def _answer_held(self) -> None:
        """Answer the state waiting for its decision once that decision's alpha and Kd are in."""
        if self._held is None or not (self._gaits["alpha"] and self._gaits["kd"]):
            return
        msg, q, dq, stamp, _since = self._held
        self._held = None
        alpha, kd = self._gaits["alpha"].popleft(), self._gaits["kd"].popleft()
        if alpha is not None:
            self.controller.apply_now(tuple(alpha), kd)  # as the ROS-free loop applies a decision
        elif kd is not None:
            self._apply("kd", kd, at_once=True)
        self.decisions_waited += 1
        self._answer(msg, q, dq, stamp)

    def _check_held(self) -> None:
        """Timer: a due decision that did not come within ``decision_timeout`` s."""
        if self._held is not None and time.monotonic() - self._held[4] > self.decision_timeout:
            self.decisions_timed_out += 1
            self._sync_paused = True
            self._release_held(f"no decision from the policy within {self.decision_timeout:g} s")

    def _release_held(self, why: str) -> None:
        """Answer a held state with the gait in force (sync paused until the policy's next gait)."""
        if self._held is None:
            return
        msg, q, dq, stamp, _since = self._held
        self._held = None
        self._forget_gaits()
        self.get_logger().warning(f"{why}: answering t = {stamp / 1e9:.3f} s with the gait in force; gaits apply "
                                  "on arrival until the policy's next one")
        self._answer(msg, q, dq, stamp)

    def _answer(self, msg: JointState, q: list[float], dq: list[float], stamp: int) -> None:
        """Compute and publish the torques for the state (and ``/hzd/step`` at a touchdown)."""
        controller = self.controller
        torques = controller.compute(q, dq)
        self._last_stamp = stamp
        self._last_state = (q, dq)
        if controller.touchdown:  # before the reply: the policy has it before the states that follow
            self._step_pub.publish(Header(stamp=msg.header.stamp, frame_id=FOOT_FRAMES[controller.stance]))
        if self._phase_pub.get_subscription_count():  # only for someone reading it (a body-state policy)
            self._phase_pub.publish(phase_to_msg(controller.tau, controller.tau_rate, msg.header.stamp,
                                                 FOOT_FRAMES[controller.stance]))
        torque_msg = self._torque_msg
        torque_msg.header.stamp = msg.header.stamp
        torque_msg.effort = torques
        if self.pairing is not None:
            torque_msg.header.frame_id = self.pairing.sign(self.source, stamp, torque_msg.effort)
        self._torque_pub.publish(torque_msg)
        self.torques_published += 1
        if self._reference_every and (stamp + TICK_NS // 2) % self._reference_every < TICK_NS:
            self._publish_reference(msg, q, dq)

    def _publish_reference(self, msg: JointState, q: list[float], dq: list[float]) -> None:
        """``/hzd/reference`` and ``/hzd/tracking_error`` of the state just answered (for a
        user tuning Kp and Kd: plot them in Foxglove or PlotJuggler)."""
        yd, dyd = self.controller.reference()
        y, dy = q[3:7], dq[3:7]  # the actuated joints, ACTUATED_JOINTS order
        for publisher, position, velocity in (
                (self._reference_pub, yd, dyd),
                (self._error_pub, [a - b for a, b in zip(y, yd)], [a - b for a, b in zip(dy, dyd)])):
            out = JointState(name=list(ACTUATED_JOINTS), position=position, velocity=velocity)
            out.header.stamp = msg.header.stamp
            out.header.frame_id = FOOT_FRAMES[self.controller.stance]
            publisher.publish(out)


def main(args: list[str] | None = None) -> int:
    """Console script / ``ros2 run rabbit_hzd_controller hzd_controller_node``."""
    return run_node(lambda context: HZDControllerNode(context=context, solo_check=PROCESS_SOLO_CHECK), args)


if __name__ == "__main__":
    sys.exit(main())
