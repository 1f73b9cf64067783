"""``hzd_controller_node``: the HZD PD controller as a ROS 2 node (1 kHz, one torque
command per state).

Subscribes ``/joint_states`` and the gait (``/hzd/alpha``, ``/hzd/kd``, transient local, so a
controller started late gets the gait in force); publishes on ``/joint_torques`` one reply
per distinct state (sensor_msgs/JointState: the four ``ACTUATED_JOINTS`` and their torques
in ``effort``, ``header.stamp`` = the stamp of the state answered, ``header.frame_id`` = this
controller instance's id, :attr:`HZDControllerNode.source`, signed with ``pairing_key`` where
the stack gave one: ``rabbit_msgs_py.pairing``), ``/hzd/step`` at each
touchdown and, while anyone subscribes, ``/hzd/phase`` (the gait phase and its rate on a
state answered, before the reply: what a body-state policy reads; on each state, or, when the
policy announces a decision every N ticks, on the state before each of its decisions, the
one it reads: :func:`~rabbit_msgs_py.decision_ticks.precedes_decision`); with ``reference_rate`` > 0
also ``/hzd/reference`` and ``/hzd/tracking_error`` (the desired outputs and the tracking
error, for tuning Kp and Kd).
The control law is :class:`rabbit_hzd_controller.controller.HZDController`, the same code
the ROS-free loop runs; which gait answers which state (the first gait, gaits queued to the
touchdown or applied at once as ``/hzd/gait_timing`` says, ``decision_sync``, resets,
re-sent states, a controller joining mid-run) is :class:`~.controller_driver.ControllerDriver`, ROS-free and
unit-tested. This node parses and validates what arrives (malformed alpha/Kd, states and
timings are rejected with a logged error; the last good gait stays in force), hands it over
and publishes what comes back.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, Header, String, UInt32

from rabbit_msgs_py import qos, strict_json, topics
from rabbit_msgs_py.conversions import (
    MessageError,
    alpha_from_msg,
    alpha_signature,
    controller_id,
    joint_state_from_bytes,
    may_carry_gait_signature,
    phase_to_msg,
    short,
    stamp_from_ns,
)
from rabbit_msgs_py.decision_ticks import (GAIT_TIMINGS, SIGNATURE_FIELD, TICK_NS, parse_gait_timing,
                                          precedes_decision, timing_settings)
from rabbit_msgs_py.cdr import JointStateWriter
from rabbit_msgs_py.joints import ACTUATED_JOINTS
from rabbit_msgs_py.parameters import Param, coerce, declare, finite, forget_secrets, overrides_given
from rabbit_msgs_py.pairing import KEY_FILE_HELP, UNSIGNED_GAIT, GaitOrder, SignedStates, resolve_key
from rabbit_msgs_py.polled import subscribe_drained
from rabbit_msgs_py.rejections import RejectionLog
from rabbit_msgs_py.node_runner import NodeStartError, destroyed_if_start_fails, run_node
from rabbit_msgs_py.solo import PROCESS_SOLO_CHECK, SOLO_CHECK_HELP, SoloStart
from rabbit_msgs_py.timers import wall_timer

from .controller import ControllerConfig, Leg, validate_alpha, validate_kd
from .controller_driver import SILENT_WALL, Answer, ControllerDriver, Repeat

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

NODE_PARAMS = {
    "gait_timing": Param("policy", "when a new gait applies: policy (as /hzd/gait_timing says; next_step until "
                                   "it does), next_step (queued to the next touchdown) or at_once (blended in "
                                   "within the step)", choices=("policy",) + GAIT_TIMINGS),
    "decision_sync": Param(False, "lockstep/paced: hold the reply to a state the policy decides on (every N ticks, "
                                  "/hzd/gait_timing at_once:N) until that decision's gait is in (the ROS-free loop "
                                  "bit for bit); not for realtime. Not given: as the simulator's /sim/mode says "
                                  "(on in lockstep and paced)"),
    "decision_timeout": Param(2.0, "decision_sync: wall s to wait for a due decision before answering with the "
                                   "gait in force, finite > 0", range=(0.001, 3600.0)),
    "reference_rate": Param(0.0, "publish /hzd/reference (the desired outputs y_d, dy_d/dt) and "
                                 "/hzd/tracking_error (y - y_d, dy/dt - dy_d/dt) this many times per s of sim time, "
                                 "on the states answered (0 = off; at most 1000, every state)", range=(0.0, 1000.0)),
    "pairing_key": Param("", "sign every torque reply with this key, so that a simulator given the same key applies "
                             "this controller's torques and no other node's (16-64 characters; run_stack makes one "
                             "per stack; read once at start, then removed so ros2 param get cannot read it). '' = "
                             "the user's own key, $ROS_HOME/rabbit_hzd/pairing_key (made on first use, owner-only); "
                             "'none' = unsigned replies, UNSAFE", dynamic=True),
    "pairing_key_file": Param("", KEY_FILE_HELP),
    "solo_check": Param(0.0, SOLO_CHECK_HELP.format(kind="controller"), range=(0.0, 60.0)),
    "stats_file": Param("", "write the controller's counts (gaits rejected and refused, torques published, "
                            "decisions waited for and given up) as JSON here when the node closes ('' = don't)"),
}
GAITLESS_WARNING_AFTER = 2.0
"""wall s: states held for want of a gait are warned about after this long (before, a start)."""
SECRET_PARAMS = ("pairing_key",)
"""Read once at start and then removed (``rabbit_msgs_py.parameters.forget_secrets``)."""


MAX_POLICIES = 8
"""Policy instances whose signed settings (and one early gait each) a keyed controller keeps."""


def _keep_newest(entries: dict, key: str, value) -> None:
    """``entries[key] = value``, the oldest entries dropped beyond :data:`MAX_POLICIES`."""
    entries[key] = value
    while len(entries) > MAX_POLICIES:
        entries.pop(next(iter(entries)))


def _setting(value) -> str:
    return ",".join(f"{v:g}" for v in value) if isinstance(value, tuple) else f"{value:g}"


class HZDControllerNode(Node):
    """Parameters: :data:`CONTROLLER_PARAMS` (``kp``, ``max_kd``, ``blend_phase`` and
    ``within_step_blend`` may change at run time; the rest are read-only) and
    :data:`NODE_PARAMS`. The rules are :class:`~.controller_driver.ControllerDriver` (ROS-free); this node
    parses and validates what arrives, hands it over and publishes what comes back."""

    @destroyed_if_start_fails
    def __init__(self, context=None, namespace: str | None = None, **overrides) -> None:
        super().__init__("hzd_controller_node", context=context, namespace=namespace)
        values = declare(self, {**CONTROLLER_PARAMS, **NODE_PARAMS}, overrides)
        forget_secrets(self, SECRET_PARAMS)
        self._given = set(overrides) | set(overrides_given(self))  # parameters set at start: a policy's wish yields
        try:
            gait_timing = values.pop("gait_timing")
            decision_sync = bool(values.pop("decision_sync"))
            decision_timeout = finite("decision_timeout", values.pop("decision_timeout"), 1e-3)
            self.pairing, self._key_source = resolve_key(values.pop("pairing_key"), file=values.pop("pairing_key_file"))
            solo_check = finite("solo_check", values.pop("solo_check"), 0.0)
            self.stats_file = values.pop("stats_file")
            rate = values.pop("reference_rate")
            self._reference_every = int(round(1e9 / rate)) if rate else 0  # ns of sim time (0: off)
            self.sync = ControllerDriver(ControllerConfig(**values), gait_timing, decision_sync, decision_timeout,
                                 mode_known="decision_sync" in self._given)
        except (ValueError, TypeError) as exc:
            raise NodeStartError(f"hzd_controller_node: {exc}") from None
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._states = SignedStates(self.pairing) if self.pairing is not None else None  # keyed: states in order
        self.torques_published = 0
        self.rejected_gaits = 0
        self.refused_gaits = 0  # gaits not signed by the paired policy (with a pairing key)
        self._announced: dict = {}
        self._settings_of: dict[str, dict] = {}  # keyed: each policy instance's signed settings (the last few)
        self._timing_of: dict[str, tuple[str, int]] = {}  # keyed: each instance's signed timing, as the settings
        self._early: dict[str, Float64MultiArray] = {}  # keyed: a policy's gait that came before its settings
        self._gait_order = GaitOrder()
        self._policy: str | None = None  # the policy instance whose signed gaits are taken
        self._policy_wall = 0.0  # wall s (monotonic) of its last gait: another is taken once it is silent
        self.rejected_states = 0
        self._rejections = RejectionLog()  # bad input: counted, logged at most once a second per kind
        self._sim_mode: str | None = None  # the simulator's mode taken from /sim/mode (kept: it never changes)
        wall_timer(self, 1.0, self._flush_rejections)  # a burst's tail is said within a second
        self._decision_period = 0  # ticks between the policy's decisions (/hzd/gait_timing; 0: per step, unknown)
        self.source = controller_id(self.get_name())  # this instance, in every reply's frame_id
        self._replies = JointStateWriter(ACTUATED_JOINTS)  # serialized replies: no message object per tick
        self._reply = b""  # the last reply sent (a re-sent state gets it again)
        self._gaitless_since: float | None = None  # wall s of the first state answered without a gait
        self.solo = SoloStart(self, "controller", solo_check, self._wire)

    def _wire(self) -> None:
        """Publishers, subscriptions and timers: once no other controller runs in this
        namespace (:class:`~rabbit_msgs_py.solo.SoloStart`)."""
        self._torque_pub = self.create_publisher(JointState, topics.JOINT_TORQUES, qos.TORQUE_QOS)
        self._step_pub = self.create_publisher(Header, topics.STEP, qos.STEP_QOS)  # (its lease: sim_node's monitor)
        self._phase_pub = self.create_publisher(JointState, topics.PHASE, qos.STREAM_QOS)
        if self._reference_every:
            self._reference_pub = self.create_publisher(JointState, topics.REFERENCE, qos.STREAM_QOS)
            self._error_pub = self.create_publisher(JointState, topics.TRACKING_ERROR, qos.STREAM_QOS)
        self._state_topic = self.resolve_topic_name(topics.JOINT_STATES)
        subscribe_drained(self, JointState, topics.JOINT_STATES, self._on_state, qos.STREAM_QOS, raw=True)
        self._read_gait_topic(Float64MultiArray, topics.ALPHA, self._on_alpha, self._unsigned_alpha)
        self._read_gait_topic(Float64, topics.KD, self._on_kd, lambda _raw: self.pairing is not None)  # (see _on_kd)
        self._read_gait_topic(String, topics.GAIT_TIMING, self._on_gait_timing, self._unsigned_timing)
        self.create_subscription(UInt32, topics.RESETS, self._on_resets, qos.STATUS_QOS)
        if "decision_sync" not in self._given:  # hold for due decisions as the simulator's stepping asks
            self.create_subscription(String, topics.SIM_MODE, self._on_sim_mode, qos.STATUS_QOS)
        self._lost_pub = self.create_publisher(UInt32, topics.DECISIONS_LOST, qos.STATUS_QOS)
        self._lost_said: int | None = None
        self._say_lost()
        wall_timer(self, 0.05, self._check)  # decision_timeout
        self.get_logger().info(f"HZD controller {self.source} (Kp = {self.config.kp:.0f} N m/rad) waiting for a gait")
        (self.get_logger().info if self.pairing else self.get_logger().warning)(f"pairing: {self._key_source}")

    # ----------------------------------------------------------------- status
    controller = property(lambda self: self.sync.controller, doc="The HZDController (None before the first state).")
    gait_timing = property(lambda self: self.sync.gait_timing)
    states_received = property(lambda self: self.sync.states_received)
    replies_repeated = property(lambda self: self.sync.replies_repeated, doc="Replies sent again for a re-sent state.")
    decisions_waited = property(lambda self: self.sync.decisions_waited, doc="Due states answered with their decision.")
    decisions_timed_out = property(lambda self: self.sync.decisions_timed_out)

    @property
    def decisions_lost(self) -> int:
        """Times the policy was found not deciding: due decisions that timed out, and silences."""
        return self.sync.decisions_timed_out + self.sync.silences

    def _check(self) -> None:
        """Every 50 ms (wall): a held decision that timed out, and the lost count if it changed."""
        self._do(self.sync.check_held())
        self._say_lost()

    def _say_lost(self) -> None:
        if self.decisions_lost != self._lost_said:
            self._lost_said = self.decisions_lost
            self._lost_pub.publish(UInt32(data=self._lost_said))

    @property
    def config(self) -> ControllerConfig:
        return self.sync.config

    @property
    def gait(self) -> tuple[list[float], float] | None:
        """The last good gait received: (alpha, 24 rad; Kd, N m s/rad), or None before both."""
        if self.sync.alpha is None or self.sync.kd is None:
            return None
        return list(self.sync.alpha), self.sync.kd

    def statistics(self) -> dict[str, int]:
        """The controller's counts (run_stack reports ``rejected`` from them)."""
        return {"rejected_gaits": self.rejected_gaits, "refused_gaits": self.refused_gaits,
                "torques_published": self.torques_published, "decisions_waited": self.sync.decisions_waited,
                "decisions_timed_out": self.sync.decisions_timed_out, "policy_silences": self.sync.silences,
                "simulator_silences": self.sync.simulator_silences}

    def close(self) -> None:
        """Write the statistics file (``stats_file``); called before the node is destroyed."""
        if self.stats_file:
            try:
                Path(self.stats_file).write_text(strict_json.dumps(self.statistics()) + "\n")
            except OSError as exc:
                self.get_logger().error(f"cannot write stats_file {self.stats_file}: {exc}")

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
        self.sync.config = config
        if self.controller is not None:
            self.controller.config = config
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------- callbacks
    def _reject(self, kind: str, topic: str, exc: Exception, keeping: str) -> None:
        self.rejected_gaits += 1
        line = self._rejections.line(kind, lambda: f"rejected {self.resolve_topic_name(topic)}: "
                                                   f"{short(str(exc), 200)}; keeping {keeping}")
        if line is not None:
            self.get_logger().error(line)

    def _read_gait_topic(self, msg_type, topic: str, handler, refused_raw=None) -> None:
        """Subscribe ``handler`` to a gait topic, read raw at the reader's depth
        (``GAIT_READER_QOS``: the policy's message stays among a flood's until taken) and
        drained (:func:`~rabbit_msgs_py.polled.subscribe_drained`); ``refused_raw(raw)`` True:
        refused on its bytes, never deserialized."""
        def on_raw(raw: bytes) -> None:
            if refused_raw is None or not refused_raw(raw):
                handler(deserialize_message(raw, msg_type))

        subscribe_drained(self, msg_type, topic, on_raw, qos.GAIT_READER_QOS, raw=True)

    def _unsigned_alpha(self, raw: bytes) -> bool:
        """Keyed: a gait whose bytes carry no signature, refused (True) before it is read."""
        if self.pairing is None or may_carry_gait_signature(raw):
            return False
        self._refuse_gait(UNSIGNED_GAIT)
        return True

    def _on_alpha(self, msg: Float64MultiArray) -> None:
        """A gait. With a pairing key only a signed one from the paired policy, new in its
        order, is taken, its Kd from its signature (an unsigned or copied one moves nothing:
        refused, logged at most once a second, not counted as a decision's part)."""
        try:
            raw = alpha_from_msg(msg)
        except MessageError as exc:
            raw, problem = None, exc
        if self.pairing is not None:
            try:
                source, count, kd = self.pairing.verify_gait(alpha_signature(msg), raw or [])
            except ValueError as exc:
                self._refuse_gait(str(exc if raw is not None else problem))
                return
            now = time.monotonic()
            if self._policy is not None and source != self._policy and now - self._policy_wall <= SILENT_WALL:
                self._refuse_gait(f"it is from policy {source} while {self._policy} is alive (a replayed bag, or "
                                  "a second policy)")
                return
            if source not in self._settings_of:  # held until its settings come: none of its gaits runs without
                _keep_newest(self._early, source, msg)
                return
            if not self._gait_order.take(source, count):
                self._refuse_gait(f"gait {count} of {source} came again after a later one")
                return
            if source != self._policy:
                if self._policy is not None:
                    self.get_logger().info(f"gaits now from policy {source}: {self._policy} was silent")
                self._policy = source
                self._adopt(self._settings_of[source])  # before its first gait
                self._follow_timing(*self._timing_of[source])
            self._policy_wall = now
        try:
            if raw is None:
                raise problem
            alpha = list(validate_alpha(raw, self.config))
        except (MessageError, ValueError) as exc:
            self._reject("alpha", topics.ALPHA, exc, "the last good gait")
            alpha = None
        self._do(self.sync.on_gait_part("alpha", alpha))
        if self.pairing is not None:
            self._take_kd(kd)

    def _on_kd(self, msg: Float64) -> None:
        """Kd alone: unsigned, so taken only without a pairing key (with one, a signed gait
        carries its Kd: this topic is then for observers)."""
        if self.pairing is None:
            self._take_kd(msg.data)

    def _take_kd(self, value: float) -> None:
        try:
            if value == 0.0:  # (the ROS-free core takes 0 as a probe of the desired outputs)
                raise ValueError("Kd must be > 0 N m s/rad: 0 leaves the joints undamped, got 0.0")
            kd = validate_kd(value, self.config)
        except ValueError as exc:
            self._reject("kd", topics.KD, exc, "the last good value")
            kd = None
        self._do(self.sync.on_gait_part("kd", kd))

    def _refuse_gait(self, why: str) -> None:
        """A gait not from the paired policy: counted and logged, never applied."""
        self.refused_gaits += 1
        topic = self.resolve_topic_name  # (called only for a line that is logged)
        line = self._rejections.line("unsigned gait", lambda: f"refused a gait on {topic(topics.ALPHA)}: "
                                                              f"{short(why, 200)}; it moves nothing")
        if line is not None:
            self.get_logger().error(line)

    def _on_gait_timing(self, msg: String) -> None:
        """The policy's gait timing (followed unless ``gait_timing`` is fixed) and the
        controller settings its spec needs (:meth:`_adopt`). With a pairing key every
        announcement, a bare timing too, counts only signed by a policy instance with the
        key, and only the paired instance's is followed: another instance's (a replay from
        an earlier run with the same key, a second policy) is kept until its first gait is
        taken; an unsigned one is refused with one line a second. Without a key, at once."""
        try:
            timing, period, settings, source = self._checked_timing(msg.data)
        except ValueError:
            self._refuse_timing(lambda: msg.data)
            return
        if source is None:
            self._adopt(settings)
            self._follow_timing(timing, period)
        else:
            _keep_newest(self._settings_of, source, settings)
            _keep_newest(self._timing_of, source, (timing, period))
            if source == self._policy:
                self._adopt(settings)
                self._follow_timing(timing, period)
        if source is not None and source in self._early:
            self._on_alpha(self._early.pop(source))

    def _checked_timing(self, data: str) -> tuple:
        """(timing, period, settings, the signing policy instance or None unkeyed) of an
        announcement; ``ValueError`` saying why it is refused."""
        timing, period = parse_gait_timing(data)
        settings = timing_settings(data)
        return timing, period, settings, self.pairing.verify_settings(data)[0] if self.pairing is not None else None

    def _refuse_timing(self, data) -> None:
        """An announcement refused: counted, and one line a second (``data()``: its text,
        read only for a line that is logged)."""
        def line() -> str:
            text = data()
            try:
                self._checked_timing(text)
                why = "refused"  # (not reached: every caller's text is refused)
            except ValueError as exc:
                why = str(exc)
            return (f"rejected {self.resolve_topic_name(topics.GAIT_TIMING)} {short(repr(text), 80)}: {why}; keeping "
                    f"{self.sync.gait_timing} and this controller's settings")

        line = self._rejections.line("gait_timing", line)
        if line is not None:
            self.get_logger().error(line)

    def _unsigned_timing(self, raw: bytes) -> bool:
        """Keyed: an announcement whose bytes carry no signature, refused (True) before it is read."""
        if self.pairing is None or SIGNATURE_FIELD.encode() in raw:
            return False
        self._refuse_timing(lambda: deserialize_message(raw, String).data)
        return True

    def _follow_timing(self, timing: str, period: int) -> None:
        """The paired policy's gait timing (``next_step`` or ``at_once`` every ``period`` ticks)."""
        self._decision_period = period
        if self.sync.follow_policy_timing:
            self._do(self.sync.on_gait_timing(timing, period))

    def _adopt(self, settings: dict) -> None:
        """The controller settings the policy announces (its spec's), taken before its gaits
        unless a parameter given at start says otherwise: then none is taken (a mix of the two
        is neither controller), and one line says which conflict. Settings the controller
        cannot run with (``ControllerConfig`` refuses them) are refused with one line."""
        if not settings or settings == self._announced:
            return
        self._announced = settings
        conflicts = {k: v for k, v in settings.items() if k in self._given and getattr(self.config, k) != v}
        if conflicts:
            self.get_logger().error(
                "the policy needs " + " ".join(f"{k}:={_setting(v)}" for k, v in conflicts.items()) + ", but this "
                "controller was started with " + " ".join(f"{k}:={_setting(getattr(self.config, k))}" for k in conflicts)
                + ": keeping this controller's settings (start it without those parameters to run the policy's spec)")
            return
        changed = {k: v for k, v in settings.items() if getattr(self.config, k) != v}
        if changed:
            try:
                config = replace(self.config, **changed)
            except ValueError as exc:
                self.get_logger().error(f"refused the policy's controller settings: {exc}; keeping this controller's")
                return
            self.sync.config = config
            if self.controller is not None:
                self.controller.config = config
            self.get_logger().info("running with the policy's controller settings: "
                                   + " ".join(f"{k}:={_setting(v)}" for k, v in changed.items()))

    def _on_sim_mode(self, msg: String) -> None:
        """The simulator's stepping (``/sim/mode``): lockstep and paced wait for each reply, so
        the reply to a state the policy decides on waits for that decision (``decision_sync``).
        With a pairing key only a mode signed with it counts; the first mode taken is kept (a
        simulator's mode never changes while it runs): any other is refused, one line a second."""
        mode, kind = msg.data, "sim_mode signature"  # each kind of refusal logged at most once a second
        try:
            if self.pairing is not None:
                mode = self.pairing.verify_settings(mode, "the simulator's mode", "simulator")[1]
            kind = "sim_mode value"
            if mode not in topics.SIM_MODES:
                raise ValueError(f"not one of {', '.join(topics.SIM_MODES)}")
            kind = "sim_mode change"
            if self._sim_mode is not None and mode != self._sim_mode:
                raise ValueError(f"the simulator runs {self._sim_mode}, and its mode does not change while it runs "
                                 "(restart this controller to follow another simulator)")
        except ValueError as exc:
            line = self._rejections.line(kind, f"rejected {self.resolve_topic_name(topics.SIM_MODE)} "
                                                     f"{short(repr(msg.data), 80)}: {exc}; decision_sync stays "
                                                     f"{'on' if self.sync.decision_sync else 'off'}")
            if line is not None:
                self.get_logger().error(line)
            return
        self._sim_mode = mode
        holds = mode in topics.REPLY_MODES
        if holds != self.sync.decision_sync:
            self.get_logger().info(f"the simulator runs {mode}: decision_sync "
                                   f"{'on (a due state waits for its decision)' if holds else 'off'}")
        self._do(self.sync.on_sim_mode(holds))

    def _on_resets(self, msg: UInt32) -> None:
        """Unkeyed: a placement count on ``/sim/resets`` (keyed, the signed states carry it)."""
        if self._states is None:
            self._do(self.sync.on_resets(msg.data))

    def _on_state(self, msg: bytes) -> None:
        """A state, serialized (taken raw: the 1 kHz path builds no message object)."""
        try:
            stamp, frame_id, q, dq = joint_state_from_bytes(msg)
        except MessageError as exc:  # counted, one line a second: a 10 kHz flood costs the loop little
            self._refuse_state("joint_states", f"ignoring malformed {self._state_topic}: {exc}")
            return
        if self._states is not None:  # keyed: signed, in order; a later placement is a reset
            try:
                placement = self._states.check(frame_id, stamp, q, dq)
            except ValueError as exc:
                self._refuse_state("unsigned state", lambda exc=exc: f"refused a state on {self._state_topic}: {exc}")
                return
            self._do(self.sync.on_resets(placement))
        self._do(self.sync.on_state(stamp, q, dq))
        missing = self.sync.missing
        if not missing:
            self._gaitless_since = None
        elif self._gaitless_since is None:
            self._gaitless_since = time.monotonic()  # a start: the policy's first gait is on its way
        elif time.monotonic() - self._gaitless_since >= GAITLESS_WARNING_AFTER:
            names = {"alpha": topics.ALPHA, "kd": topics.KD, "gait_timing": topics.GAIT_TIMING}
            waiting = " and ".join(self.resolve_topic_name(names[m]) for m in ("alpha", "kd") if m in missing)
            if "gait_timing" in missing:
                waiting = " and ".join(filter(None, (waiting, self.resolve_topic_name(topics.GAIT_TIMING))))
            self.get_logger().warning(f"no gait yet (waiting for {waiting}); the state will be answered once it is "
                                      "complete", throttle_duration_sec=2.0)

    def _refuse_state(self, kind: str, text) -> None:
        self.rejected_states += 1
        line = self._rejections.line(kind, text)
        if line is not None:
            self.get_logger().error(line)

    # -------------------------------------------------------------- actions
    def _do(self, actions: list) -> None:
        """Carry out what :class:`ControllerDriver` returned, in order."""
        for action in actions:
            if isinstance(action, Answer):
                self._answer(action)
            elif isinstance(action, Repeat):
                self._torque_pub.publish(self._reply)  # a re-send: the same reply again
            elif action.level == "warning":  # (rclpy wants one severity per call site)
                self.get_logger().warning(action.text)
            else:
                self.get_logger().info(action.text)

    def _answer(self, answer: Answer) -> None:
        """Publish the torques for the state (and ``/hzd/step`` at a touchdown)."""
        stamp = stamp_from_ns(answer.stamp)
        frame = FOOT_FRAMES[answer.stance]
        if answer.touchdown:  # before the reply: the policy has it before the states that follow
            self._step_pub.publish(Header(stamp=stamp, frame_id=frame))
        if self._phase_pub.get_subscription_count() and precedes_decision(answer.stamp, self._decision_period):
            self._phase_pub.publish(phase_to_msg(answer.tau, answer.tau_rate, stamp, frame))
        torques = answer.torques
        frame_id = self.pairing.sign(self.source, answer.stamp, torques) if self.pairing is not None else self.source
        self._reply = self._replies.bytes(answer.stamp, frame_id, (), (), torques)
        self._torque_pub.publish(self._reply)
        self.torques_published += 1
        if self._reference_every and (answer.stamp + TICK_NS // 2) % self._reference_every < TICK_NS:
            self._publish_reference(stamp, frame)

    def _publish_reference(self, stamp, frame: str) -> None:
        """``/hzd/reference`` and ``/hzd/tracking_error`` of the state just answered (for a
        user tuning Kp and Kd: plot them in Foxglove or PlotJuggler)."""
        yd, dyd = self.controller.reference()
        q, dq = self.sync.last_state
        y, dy = q[3:7], dq[3:7]  # the actuated joints, ACTUATED_JOINTS order
        for publisher, position, velocity in (
                (self._reference_pub, yd, dyd),
                (self._error_pub, [a - b for a, b in zip(y, yd)], [a - b for a, b in zip(dy, dyd)])):
            out = JointState(name=list(ACTUATED_JOINTS), position=position, velocity=velocity)
            out.header.stamp = stamp
            out.header.frame_id = frame
            publisher.publish(out)


def main(args: list[str] | None = None) -> int:
    """Console script / ``ros2 run rabbit_hzd_controller hzd_controller_node``."""
    return run_node(lambda context: HZDControllerNode(context=context, solo_check=PROCESS_SOLO_CHECK), args)


if __name__ == "__main__":
    sys.exit(main())
