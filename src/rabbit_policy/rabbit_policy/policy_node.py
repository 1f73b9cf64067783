"""``policy_node``: picks the gait (alpha, Kd) for each step from the commanded speed and the
averaged hip speed, as in the paper's Fig. 2.

Subscribes ``/cmd_speed`` (m/s; or ``/cmd_vel``, geometry_msgs/Twist, linear.x), the
simulator's states in batches (``/sim/state_batch``, about 50 a second, every state in them;
``hip_source:=hip_velocity`` takes ``/hip_velocity`` at 1 kHz instead, for a robot or
simulator that publishes only that) and ``/hzd/step`` (touchdowns, from the controller);
publishes ``/hzd/alpha`` and ``/hzd/kd`` (transient local) once at
start and then at every step, and with each gait ``/sim/initial_state`` (transient local):
the state at phase 0 of that gait with the hip moving at ``initial_speed``, where the
simulator starts and resets (it knows no gait itself). The policy's inputs are the paper's: the commanded speed v_d,
the mean hip speed and the mean of (v_d - hip speed) over the last step (at most
``window`` samples). When it decides and over which samples is
:class:`rabbit_policy.runtime.decision_clock.DecisionClock`, the rule the ROS-free closed
loop runs too (a sample is the state after a step; a step's decision comes with the first
state of the next one); the decision takes effect at the next touchdown (the controller
queues it). The rules live in :class:`rabbit_policy.policy_driver.PolicyDriver` (ROS-free);
this node turns messages into its events and its actions into messages. Parameters:

* ``policy``: ``classic`` (classic HZD gait library, the paper's baseline; the default, as
  in every script) or ``learned`` (the HZD-RL network: the shipped one unless
  ``policy_file``); ``library`` is an alias of classic.
* ``library_mode``: ``nearest`` gait or ``interpolate`` between the two around v_d.
* ``gait_dir``: gait library directory ('' = the packaged one).
* ``policy_file``: learned controller spec (.yaml) or training checkpoint (.pt) ('' = the packaged spec).
* ``spec_file``: a controller spec of any kind (classic, recovery or learned): the controller
  is the file's kind ('' = none: ``policy`` and ``policy_file`` say).
* ``initial_speed``: v_d before the first ``/cmd_speed`` and the hip speed of the initial
  state (m/s).
* ``speed_integral``: classic only, Westervelt's event-based speed integral, gain in 1/s
  (0 = off, the default): the gait for v_d plus the integral of the mean speed error, held
  within +-0.2 m/s (:mod:`rabbit_policy.runtime.speed_integral`).
* ``min_speed``, ``max_speed``: commands outside are clamped with a warning (0.7, 1.5).
* ``window``: longest averaging window (ticks, 1000).
* ``max_command_step``: command rate limit, m/s per step (0.0 = none, the default): the
  policy sees a command that follows ``/cmd_speed`` by at most this much per step.
* ``decision_period``: -1 (default) decides as the policy was made to: classic every 20
  ticks, a learned policy as it was trained; 0 decides once per step as above; N > 0 every N ticks of
  sim time (hip-speed stamps) on the moving average over the last step's duration (at most
  ``decision_window`` ticks), as the paper evaluates its network. ``/hzd/gait_timing``
  tells the controller which (``at_once`` for periodic decisions).

A policy that reads the body state inside the step (trained with features ``body``; it
decides every N ticks) takes it from the same states (``/joint_states`` with
``hip_source:=hip_velocity``) and also subscribes ``/hzd/phase`` (the
controller's phase, published while anyone subscribes): each due decision is held until the
state it is made on and the controller's phase on the state before it are in
(:class:`rabbit_policy.runtime.body.BodyStateBuffer`, the loops' rule: a lockstep stack runs
it bit for bit as the ROS-free loop). A decision whose parts have not come within 50 ticks
(a controller that publishes no phase) is given up with an error; the gait in force stays.

NaN/inf commands are rejected with an error; the last good command stays in force.
"""

from __future__ import annotations

import sys
import time

from geometry_msgs.msg import Twist, TwistStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, Header, String, UInt32

from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.conversions import (MessageError, alpha_to_msg, controller_id, joint_state_vectors, phase_from_msg,
                                        stamp_to_ns, batch_states_or_log)
from rabbit_msgs_py.decision_ticks import DecisionTiming, gait_timing
from rabbit_msgs_py.joints import JOINT_NAMES
from rabbit_msgs_py.log_lines import LineLogger
from rabbit_msgs_py.pairing import KEY_FILE_HELP, SignedBatches, resolve_key
from rabbit_msgs_py.parameters import Param, coerce, declare, finite, forget_secrets
from rabbit_msgs_py.polled import subscribe_drained
from rabbit_msgs_py.node_runner import NodeStartError, destroyed_if_start_fails, run_node
from rabbit_msgs_py.solo import PROCESS_SOLO_CHECK, SOLO_CHECK_HELP, SoloStart
from rabbit_msgs_py.timers import wall_timer
from rabbit_policy.policy_driver import Gait, Log, PolicyDriver, PolicySettings, Scheduled
from rabbit_policy.runtime.speed_command import COMMAND_RANGE
from rabbit_policy.runtime.policies import CONTROLLER_CHOICES, LIBRARY_MODES, Policy, PolicyUnavailable, controller_name, controller_settings
from rabbit_policy.spec.make import make_policy, spec_kind


HIP_SOURCES = ("state_batch", "hip_velocity")
"""Where policy_node takes the hip speed from (parameter ``hip_source``)."""

COMMAND_RATE = 2.0
"""m/s per s: ``command_rate``'s default, a 0.8 m/s change within 0.4 s (about a step), so that no
sequence of commands (a flood cycling 0.7 and 1.5 m/s every ms) makes the command jump."""
POLICY_PARAMS = {
    "policy": Param("classic", "classic (the HZD gait library; aliases library and hzd), learned (the HZD-RL "
                               "network; alias rl) or recovery (classic plus the model-based push-recovery rule)",
                    choices=CONTROLLER_CHOICES),
    "library_mode": Param("interpolate", "classic: interpolate (the calibrated blend that walks at the command) "
                                         "or nearest gait", choices=LIBRARY_MODES),
    "gait_dir": Param("", "classic: gait library directory ('' = the packaged one)"),
    "policy_file": Param("", "learned: controller spec (.yaml) or training checkpoint (.pt) ('' = the packaged "
                                 "spec, rabbit_policy/controllers/learned.yaml)"),
    "spec_file": Param("", "a controller spec of any kind (classic, recovery or learned; docs/controller_spec.md): "
                           "the controller is the file's kind ('' = none: policy and policy_file say)"),
    "initial_speed": Param(1.0, "command before the first /cmd_speed and hip speed of the initial state, m/s, "
                                "within [min_speed, max_speed]", range=COMMAND_RANGE),
    "speed_integral": Param(0.0, "classic: event-based speed integral gain, 1/s (0 = off): the gait for the command "
                                 "plus the bounded integral of the speed error", range=(0.0, 100.0)),
    "min_speed": Param(COMMAND_RANGE[0], "lowest command, m/s, not above max_speed; /cmd_speed below is clamped "
                                         "with a warning (within the gait library's 0.7-1.5, the speeds the "
                                         "controllers walk)", dynamic=True, range=COMMAND_RANGE),
    "max_speed": Param(COMMAND_RANGE[1], "highest command, m/s, not below min_speed; /cmd_speed above is clamped "
                                         "with a warning (within the gait library's 0.7-1.5)", dynamic=True,
                       range=COMMAND_RANGE),
    "hip_source": Param("state_batch", "where the hip speed (and a body-state policy's state) comes from: "
                                       "state_batch (/sim/state_batch, every state in batches) or hip_velocity "
                                       "(/hip_velocity, and /joint_states for a body-state policy, each at 1 kHz)",
                        choices=HIP_SOURCES),
    "window": Param(1000, "longest averaging window of the observation, ticks (1 ms), >= 1", range=(1, 100000)),
    "max_command_step": Param(0.0, "command rate limit, m/s per step (0 = none)", range=(0.0, 10.0)),
    "command_rate": Param(COMMAND_RATE, "a command on /cmd_speed or /cmd_vel is followed at most this fast, m/s per s "
                                        "of sim time (0 = at once); the speed schedule's changes apply at once, as on "
                                        "the fast path", range=(0.0, 100.0)),
    "decision_period": Param(-1, "-1: the policy's own (classic: every 20 ticks; learned: as trained); 0: once per "
                                 "step (at /hzd/step); N > 0: every N ticks (1 ms) of sim time, the gait applied "
                                 "at once", range=(-1, 100000)),
    "decision_window": Param(0, "decision_period > 0: moving-average window, ticks (0 = the policy's own: its "
                                "spec's decision.window_ticks)", range=(0, 100000)),
    "speed_schedule": Param("", "speed changes at exact sim times after the start, 'T:V,...' (s, m/s; T > 0, at "
                                "least 0.1 s apart), applied at the first state at or after T as walk.py --schedule "
                                "applies them (a /cmd_speed in between holds until the next change); again after a "
                                "reset. run_stack sets it: '' = none"),
    "solo_check": Param(0.0, SOLO_CHECK_HELP.format(kind="policy"), range=(0.0, 60.0)),
    "pairing_key": Param("", "sign every gait with this key, so that a controller given the same key applies this "
                             "policy's gaits and no other node's (16-64 characters; run_stack makes one per stack; "
                             "read once at start, then removed so ros2 param get cannot read it). '' = the user's "
                             "own key, $ROS_HOME/rabbit_hzd/pairing_key (made on first use, owner-only); 'none' = "
                             "unsigned gaits, UNSAFE", dynamic=True),
    "pairing_key_file": Param("", KEY_FILE_HELP),
}



def spec_choice(policy: str, policy_file: str, spec_file: str) -> tuple[str, str]:
    """(controller kind, its file) from the ``policy``, ``policy_file`` and ``spec_file``
    parameters: a ``spec_file`` is the controller its file says (``policy`` left at classic,
    or the same kind; no ``policy_file`` beside it). ``ValueError`` with one line otherwise."""
    if not spec_file:
        return policy, policy_file
    if policy_file:
        raise ValueError("spec_file and policy_file both name the controller's file: give one")
    kind = spec_kind(spec_file)
    if controller_name(policy) not in ("classic", kind):
        raise ValueError(f"spec_file {spec_file} is a {kind} controller, not {policy}: leave policy out")
    return kind, spec_file


SECRET_PARAMS = ("pairing_key",)
"""Read once at start and then removed (``rabbit_msgs_py.parameters.forget_secrets``)."""


class PolicyNode(Node):
    """The gait policy node: parameters, topics and timers around a :class:`PolicyDriver`."""

    @destroyed_if_start_fails
    def __init__(self, context=None, namespace: str | None = None, built_policy: Policy | None = None,
                 **overrides) -> None:
        """``built_policy``: the policy the parameters describe, already built (an in-process
        stack builds it once, to refuse a bad one before any node starts); None: built here."""
        super().__init__("policy_node", context=context, namespace=namespace)
        values = declare(self, POLICY_PARAMS, overrides)
        forget_secrets(self, SECRET_PARAMS)
        try:
            self.pairing, key_source = resolve_key(values["pairing_key"], file=values["pairing_key_file"])
            self._batches = SignedBatches(self.pairing) if self.pairing is not None else None  # keyed: signed only
            low = finite("min_speed", values["min_speed"], *POLICY_PARAMS["min_speed"].range)
            high = finite("max_speed", values["max_speed"], *POLICY_PARAMS["max_speed"].range)
            kind, policy_file = spec_choice(values["policy"], values["policy_file"], values["spec_file"])
            policy = built_policy if built_policy is not None else make_policy(
                kind, values["gait_dir"] or None, values["library_mode"], policy_file or None,
                finite("max_command_step", values["max_command_step"], 0.0),
                DecisionTiming.parse(values["decision_period"]), finite("speed_integral", values["speed_integral"], 0.0))
            self.core = PolicyDriver(policy, PolicySettings(
                low, high, values["initial_speed"],
                values["window"], values["decision_window"], values["speed_schedule"],
                self.resolve_topic_name(topics.PHASE), finite("command_rate", values["command_rate"], 0.0)))
        except (PolicyUnavailable, ValueError) as exc:
            raise NodeStartError(f"policy_node: {exc}") from None
        self._hip_source = values["hip_source"]  # (one of HIP_SOURCES: declare checks the choices)
        self._settings = controller_settings(policy)  # announced on /hzd/gait_timing: the controller takes them
        self.add_on_set_parameters_callback(self._on_set_parameters)
        wall_timer(self, 1.0, lambda: self._do(self.core.flush()))  # a burst's tail is said within a second
        wall_timer(self, 0.25, lambda: self._do(self.core.check_simulation(time.monotonic())))  # a lost simulator
        self._log = LineLogger(self.get_logger())  # the core's lines: throttled by key
        self._warned_planar = False
        self.source = controller_id(self.get_name())  # this instance, in its gaits' signatures
        self.gaits_published = 0
        (self.get_logger().info if self.pairing else self.get_logger().warning)(
            f"pairing: {key_source.replace('torques', 'gaits')}")
        self.solo = SoloStart(self, "policy", values["solo_check"], self._wire)

    # the core's state, for scripts and tests
    policy = property(lambda self: self.core.policy)
    desired_speed = property(lambda self: self.core.desired_speed)
    min_speed = property(lambda self: self.core.min_speed)
    max_speed = property(lambda self: self.core.max_speed)
    decision_period = property(lambda self: self.core.decision_period)
    needs_body = property(lambda self: self.core.needs_body)
    decisions = property(lambda self: self.core.decisions)
    rejected_commands = property(lambda self: self.core.rejected_commands)
    decisions_given_up = property(lambda self: self.core.decisions_given_up)
    simulation_silences = property(lambda self: self.core.simulation_silences)
    last_observation = property(lambda self: self.core.last_observation)
    clock = property(lambda self: self.core.clock)
    body = property(lambda self: self.core.body)

    def _wire(self) -> None:
        """Publishers and subscriptions, and the first gait: once no other policy runs in
        this namespace (:class:`~rabbit_msgs_py.solo.SoloStart`)."""
        self._alpha_pub = self.create_publisher(Float64MultiArray, topics.ALPHA, qos.GAIT_QOS)
        self._kd_pub = self.create_publisher(Float64, topics.KD, qos.GAIT_QOS)
        self._initial_state_pub = self.create_publisher(JointState, topics.INITIAL_STATE, qos.GAIT_QOS)
        self._timing_pub = self.create_publisher(String, topics.GAIT_TIMING, qos.GAIT_QOS)
        timing = gait_timing(self.core.decision_period, self._settings)
        self._timing_pub.publish(String(data=self.pairing.sign_settings(self.source, timing)
                                        if self.pairing is not None else timing))
        self._speed_pub = self.create_publisher(Float64, topics.CMD_SPEED, qos.COMMAND_QOS)  # scheduled commands
        # every input a stranger can flood drained (a burst costs one executor callback) and refused with a
        # topic name resolved once here
        self._topic = {name: self.resolve_topic_name(name) for name in (
            topics.CMD_SPEED, topics.CMD_VEL, topics.STATE_BATCH, topics.HIP_VELOCITY, topics.JOINT_STATES,
            topics.PHASE)}
        subscribe_drained(self, Float64, topics.CMD_SPEED, self._on_cmd_speed, qos.COMMAND_QOS)
        subscribe_drained(self, Twist, topics.CMD_VEL, self._on_cmd_vel, qos.COMMAND_QOS)
        if self._hip_source == "state_batch":
            self._batch_topic = self._topic[topics.STATE_BATCH]
            subscribe_drained(self, Float64MultiArray, topics.STATE_BATCH, self._on_state_batch, qos.BATCH_QOS,
                              raw=True)
        else:
            subscribe_drained(self, TwistStamped, topics.HIP_VELOCITY, self._on_hip_velocity, qos.HIP_VELOCITY_QOS)
        self.create_subscription(Header, topics.STEP, lambda msg: self._do(self.core.on_step(stamp_to_ns(msg.stamp))),
                                 qos.EVENT_QOS)
        self.create_subscription(UInt32, topics.RESETS, lambda msg: self.core.on_placed(msg.data), qos.STATUS_QOS)
        if self.core.body is not None:
            if self._hip_source == "hip_velocity":
                subscribe_drained(self, JointState, topics.JOINT_STATES, self._on_joint_state, qos.STREAM_QOS)
            subscribe_drained(self, JointState, topics.PHASE, self._on_phase, qos.STREAM_QOS)
        self._do(self.core.start())
        self.get_logger().info(f"policy {self.core.policy.name}: {self.core.desired_speed:.2f} m/s; "
                               f"send speeds on {self.resolve_topic_name(topics.CMD_SPEED)}")

    # -------------------------------------------------------------- callbacks
    def _on_set_parameters(self, parameters: list) -> SetParametersResult:
        """``min_speed``/``max_speed`` at run time, validated as at start (the command in
        force is clamped into the new range); read-only ones are refused by rclpy."""
        low, high = self.core.min_speed, self.core.max_speed
        for param in parameters:
            if param.name not in ("min_speed", "max_speed"):
                continue
            try:
                value = finite(param.name, coerce(param.name, param.value, 0.0), *POLICY_PARAMS[param.name].range)
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
            low, high = (value, high) if param.name == "min_speed" else (low, value)
        try:
            self.core.set_range(low, high)
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _on_cmd_speed(self, msg: Float64) -> None:
        self._do(self.core.on_cmd_speed(msg.data, self._topic[topics.CMD_SPEED]))

    def _on_cmd_vel(self, msg: Twist) -> None:
        """``/cmd_vel``: linear.x is the commanded speed; RABBIT walks straight in its plane."""
        topic = self._topic[topics.CMD_VEL]
        if not self._warned_planar and (msg.linear.y or msg.linear.z or msg.angular.x or msg.angular.y
                                        or msg.angular.z):
            self._warned_planar = True
            self.get_logger().warning(f"{topic}: RABBIT walks straight in its plane; only linear.x (the speed) is "
                                      "used, the other fields are ignored (said once)")
        self._do(self.core.on_command(msg.linear.x, topic))

    def _on_hip_velocity(self, msg: TwistStamped) -> None:
        try:
            self._do(self.core.on_hip_velocity(stamp_to_ns(msg.header.stamp), msg.twist.linear.x))
        except ValueError as exc:
            self._refused("hip_velocity", f"ignoring {self._topic[topics.HIP_VELOCITY]}: {exc}")

    def _refused(self, kind: str, line: str) -> None:
        """Refused input of ``kind``: counted, logged at most once a second with the core's
        rejections (rclpy's own throttle costs more per call than a flood leaves)."""
        text = self.core.rejections.line(kind, line)
        if text is not None:
            self.get_logger().error(text)

    def _batch_refused(self, line: str) -> None:
        self._refused("state_batch", line)

    def _on_state_batch(self, raw: bytes) -> None:
        """The simulator's states (the batch's serialized bytes), oldest first: each its hip
        speed (and, for a body-state policy, its body state first), as one ``/hip_velocity``
        and ``/joint_states`` each."""
        body = self.core.body is not None
        for state in batch_states_or_log(raw, self._batch_topic, self._batch_refused, self._batches):
            if body:
                self._do(self.core.on_body_state(state.stamp, state.position, state.velocity))
            try:
                self._do(self.core.on_hip_velocity(state.stamp, state.velocity[0]))
            except ValueError as exc:
                self._refused("state_batch", f"ignoring a state in {self._batch_topic}: {exc}")

    def _on_joint_state(self, msg: JointState) -> None:
        try:
            q, dq = joint_state_vectors(msg.name, msg.position, msg.velocity)
        except MessageError as exc:
            self._refused("joint_states", f"ignoring {self._topic[topics.JOINT_STATES]}: {exc}")
            return
        self._do(self.core.on_body_state(stamp_to_ns(msg.header.stamp), q, dq))

    def _on_phase(self, msg: JointState) -> None:
        try:
            stamp, tau, rate = phase_from_msg(msg)
        except MessageError as exc:
            self._refused("phase", f"ignoring {self._topic[topics.PHASE]}: {exc}")
            return
        self._do(self.core.on_phase(stamp, tau, rate))

    # ---------------------------------------------------------------- actions
    def _do(self, actions: list) -> None:
        for action in actions:
            if isinstance(action, Gait):
                alpha, kd = action.command.alpha, float(action.command.kd)
                self.gaits_published += 1
                signature = (self.pairing.gait_signature(self.source, self.gaits_published, alpha, kd)
                             if self.pairing is not None else "")
                self._alpha_pub.publish(alpha_to_msg(alpha, signature))
                self._kd_pub.publish(Float64(data=kd))
                if action.same_initial_state:
                    pass  # the one published with an earlier gait (transient local) stands
                elif action.initial_state is None:
                    self.get_logger().error(f"no initial state on the gait just published: {action.error}",
                                            throttle_duration_sec=5.0)
                else:
                    qpos, qvel = action.initial_state
                    self._initial_state_pub.publish(JointState(name=list(JOINT_NAMES), position=qpos, velocity=qvel))
            elif isinstance(action, Scheduled):
                self._speed_pub.publish(Float64(data=action.speed))
            elif isinstance(action, Log):
                self._log(action)


def main(args: list[str] | None = None) -> int:
    """Console script / ``ros2 run rabbit_policy policy_node``."""
    return run_node(lambda context: PolicyNode(context=context, solo_check=PROCESS_SOLO_CHECK), args)


if __name__ == "__main__":
    sys.exit(main())
