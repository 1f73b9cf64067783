"""``policy_node``: picks the gait (alpha, Kd) for each step from the commanded speed and the
averaged hip speed, as in the paper's Fig. 2.

Subscribes ``/cmd_speed`` (m/s; or ``/cmd_vel``, geometry_msgs/Twist, linear.x),
``/hip_velocity`` (1 kHz) and ``/hzd/step`` (touchdowns, from the controller); publishes ``/hzd/alpha`` and ``/hzd/kd`` (transient local) once at
start and then at every step, and with each gait ``/sim/initial_state`` (transient local):
the state at phase 0 of that gait with the hip moving at ``initial_speed``, where the
simulator starts and resets (it knows no gait itself). The policy's inputs are the paper's: the commanded speed v_d,
the mean hip speed and the mean of (v_d - hip speed) over the last step (at most
``window`` samples). When it decides and over which samples is
:class:`rabbit_policy.runtime.decision_clock.DecisionClock`, the rule the ROS-free closed
loop runs too (a sample is the state after a step; a step's decision comes with the first
state of the next one); the decision takes effect at the next touchdown (the controller
queues it). Parameters:

* ``policy``: ``classic`` (classic HZD gait library, the paper's baseline; the default, as
  in every script) or ``learned`` (the HZD-RL network: the shipped one unless
  ``policy_file``); ``library`` is an alias of classic.
* ``library_mode``: ``nearest`` gait or ``interpolate`` between the two around v_d.
* ``gait_dir``: gait library directory ('' = the packaged one).
* ``policy_file``: learned controller spec (.yaml) or training checkpoint (.pt) ('' = the packaged spec).
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
decides every N ticks) also subscribes ``/joint_states`` and ``/hzd/phase`` (the
controller's phase, published while anyone subscribes): each due decision is held until the
state it is made on and the controller's phase on the state before it are in
(:class:`rabbit_policy.runtime.body.BodyStateBuffer`, the loops' rule: a lockstep stack runs
it bit for bit as the ROS-free loop). A decision whose parts have not come within 50 ticks
(a controller that publishes no phase) is given up with an error; the gait in force stays.

NaN/inf commands are rejected with an error; the last good command stays in force.
"""

from __future__ import annotations

import sys
from collections import deque
from dataclasses import replace

from geometry_msgs.msg import Twist, TwistStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, Header, String, UInt32

from rabbit_hzd_controller.gait_state import state_on_gait
from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.joints import JOINT_NAMES
from rabbit_msgs_py.parameters import Param, coerce, declare, finite
from rabbit_msgs_py.conversions import MessageError, alpha_to_msg, joint_state_vectors, phase_from_msg, stamp_to_ns
from rabbit_msgs_py.decision_ticks import TICK_NS, DecisionTiming, gait_timing
from rabbit_msgs_py.rejections import RejectionLog
from rabbit_msgs_py.runtime import NodeStartError, destroyed_if_start_fails, run_node
from rabbit_msgs_py.solo import PROCESS_SOLO_CHECK, SOLO_CHECK_HELP, SoloStart
from rabbit_msgs_py.timers import wall_timer

from rabbit_policy.runtime.policies import (
    CONTROLLER_CHOICES,
    DEFAULT_DECISION_WINDOW,
    LIBRARY_MODES,
    GaitCommand,
    Policy,
    PolicyUnavailable,
    controller_settings,
    decision_period,
    first_command,
    make_policy,
    reset_policy,
)
from rabbit_policy.runtime import exact_sum
from rabbit_policy.runtime.body import BodyStateBuffer
from rabbit_policy.runtime.decision_clock import DecisionClock
from rabbit_policy.runtime.commands import COMMAND_RANGE, clamp_message, clamp_speed
from rabbit_policy.runtime.speed_schedule import SpeedSchedule
from rabbit_policy.runtime.speed_window import Observation
from rabbit_policy.experiment.scenario import parse_schedule, validate_schedule


POLICY_PARAMS = {
    "policy": Param("classic", "classic (the HZD gait library; alias library), learned (the HZD-RL network) or "
                               "recovery (classic plus the model-based push-recovery rule)", choices=CONTROLLER_CHOICES),
    "library_mode": Param("interpolate", "classic: interpolate (the calibrated blend that walks at the command) "
                                         "or nearest gait", choices=LIBRARY_MODES),
    "gait_dir": Param("", "classic: gait library directory ('' = the packaged one)"),
    "policy_file": Param("", "learned: controller spec (.yaml) or training checkpoint (.pt) ('' = the packaged "
                                 "spec, rabbit_policy/controllers/learned.yaml)"),
    "initial_speed": Param(1.0, "command before the first /cmd_speed and hip speed of the initial state, m/s, "
                                "within [min_speed, max_speed]", range=(0.1, 3.0)),
    "speed_integral": Param(0.0, "classic: event-based speed integral gain, 1/s (0 = off): the gait for the command "
                                 "plus the bounded integral of the speed error", range=(0.0, 100.0)),
    "min_speed": Param(COMMAND_RANGE[0], "lowest command, m/s, not above max_speed; /cmd_speed below is clamped", dynamic=True,
                       range=(0.1, 3.0)),
    "max_speed": Param(COMMAND_RANGE[1], "highest command, m/s, not below min_speed; /cmd_speed above is clamped", dynamic=True,
                       range=(0.1, 3.0)),
    "window": Param(1000, "longest averaging window of the observation, ticks (1 ms), >= 1", range=(1, 100000)),
    "max_command_step": Param(0.0, "command rate limit, m/s per step (0 = none)", range=(0.0, 10.0)),
    "decision_period": Param(-1, "-1: the policy's own (classic: every 20 ticks; learned: as trained); 0: once per "
                                 "step (at /hzd/step); N > 0: every N ticks (1 ms) of sim time, the gait applied "
                                 "at once", range=(-1, 100000)),
    "decision_window": Param(DEFAULT_DECISION_WINDOW, "decision_period > 0: moving-average window, ticks, >= 1",
                             range=(1, 100000)),
    "speed_schedule": Param("", "speed changes at exact sim times after the start, 'T:V,...' (s, m/s; T > 0, at "
                                "least 0.1 s apart), applied at the first state at or after T as walk.py --schedule "
                                "applies them (a /cmd_speed in between holds until the next change); again after a "
                                "reset. run_stack sets it: '' = none"),
    "solo_check": Param(0.0, SOLO_CHECK_HELP.format(kind="policy"), range=(0.0, 60.0)),
}


SCHEDULE_SOURCE = "speed_schedule"
"""Where a scheduled command comes from, in log lines."""


def speed_schedule(text: str, initial_speed: float) -> SpeedSchedule | None:
    """The ``speed_schedule`` parameter: None for ''; else its changes, checked as walk.py's
    schedule is (``ValueError`` with one line)."""
    if not text:
        return None
    try:
        changes = parse_schedule(text)
        validate_schedule(((0.0, initial_speed), *changes))
    except ValueError as exc:
        raise ValueError(f"speed_schedule: {exc}") from None
    return SpeedSchedule(changes)


class PolicyNode(Node):
    """The gait policy node."""

    @destroyed_if_start_fails
    def __init__(self, context=None, namespace: str | None = None, built_policy: Policy | None = None,
                 **overrides) -> None:
        """``built_policy``: the policy the parameters describe, already built (an in-process
        stack builds it once, to refuse a bad one before any node starts); None: built here."""
        super().__init__("policy_node", context=context, namespace=namespace)
        values = declare(self, POLICY_PARAMS, overrides)
        try:
            self.min_speed = finite("min_speed", values["min_speed"], *POLICY_PARAMS["min_speed"].range)
            self.max_speed = finite("max_speed", values["max_speed"], *POLICY_PARAMS["max_speed"].range)
            if not self.min_speed <= self.max_speed:
                raise ValueError(f"min_speed ({self.min_speed}) must not be above max_speed ({self.max_speed})")
            self.policy = built_policy if built_policy is not None else make_policy(
                values["policy"], values["gait_dir"] or None, values["library_mode"], values["policy_file"] or None,
                finite("max_command_step", values["max_command_step"], 0.0),
                DecisionTiming.parse(values["decision_period"]), finite("speed_integral", values["speed_integral"], 0.0))
            if values["window"] < 1:
                raise ValueError(f"window must be >= 1 tick, got {values['window']}")
            if values["decision_window"] < 1:
                raise ValueError(f"decision_window must be >= 1 tick, got {values['decision_window']}")
            self.decision_period = decision_period(self.policy)
            self.needs_body = bool(getattr(self.policy, "needs_body", False))
            if self.needs_body and not self.decision_period:
                raise ValueError("this policy reads the body state inside the step and decides every N ticks; "
                                 "decision_period 0 (once per step) cannot run it")
            settings = controller_settings(self.policy)
            if settings:  # the controller is a node of its own: say what it must run with
                self.get_logger().info(f"{self.policy.name} needs hzd_controller_node to run with "
                                       + " ".join(f"{k}:={v}" for k, v in settings.items())
                                       + " (run_stack sets them)")
            # when to decide and over which samples: the closed loop's rule (stamps in ns)
            self.clock = DecisionClock(self.decision_period,
                                       values["decision_window"] if self.decision_period else values["window"],
                                       tick=TICK_NS)
            exact_sum.warm()  # the window's compiled sum loaded now, not on the first decision
            self.desired_speed = finite("initial_speed", values["initial_speed"], self.min_speed, self.max_speed)
            self.initial_speed = self.desired_speed
            self.schedule = speed_schedule(values["speed_schedule"], self.initial_speed)
        except (PolicyUnavailable, ValueError) as exc:
            raise NodeStartError(f"policy_node: {exc}") from None
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self.decisions = 0
        self.rejected_commands = 0
        self._rejections = RejectionLog()  # bad input: counted, logged at most once a second per kind
        wall_timer(self, 1.0, self._flush_rejections)  # a burst's tail is said within a second
        self.last_observation: Observation | None = None
        # a body-state policy: the state and the controller's phase, its decisions held until both are in
        self.body: BodyStateBuffer | None = BodyStateBuffer(TICK_NS) if self.needs_body else None
        self._awaiting: deque[tuple[int, Observation]] = deque()
        self.decisions_given_up = 0
        self._warned_planar = False
        self._placements = 0
        self._echoes: list[float] = []  # scheduled commands published on /cmd_speed, not yet heard back
        self.solo = SoloStart(self, "policy", values["solo_check"], self._wire)

    def _wire(self) -> None:
        """Publishers and subscriptions, and the first gait: once no other policy runs in
        this namespace (:class:`~rabbit_msgs_py.solo.SoloStart`)."""
        self._alpha_pub = self.create_publisher(Float64MultiArray, topics.ALPHA, qos.GAIT_QOS)
        self._kd_pub = self.create_publisher(Float64, topics.KD, qos.GAIT_QOS)
        self._initial_state_pub = self.create_publisher(JointState, topics.INITIAL_STATE, qos.GAIT_QOS)
        self._timing_pub = self.create_publisher(String, topics.GAIT_TIMING, qos.GAIT_QOS)
        self._timing_pub.publish(String(data=gait_timing(self.decision_period)))
        self._speed_pub = self.create_publisher(Float64, topics.CMD_SPEED, qos.COMMAND_QOS)  # scheduled commands
        self.create_subscription(Float64, topics.CMD_SPEED, self._on_cmd_speed, qos.COMMAND_QOS)
        self.create_subscription(Twist, topics.CMD_VEL, self._on_cmd_vel, qos.COMMAND_QOS)
        self.create_subscription(TwistStamped, topics.HIP_VELOCITY, self._on_hip_velocity, qos.HIP_VELOCITY_QOS)
        self.create_subscription(Header, topics.STEP, self._on_step, qos.EVENT_QOS)
        self.create_subscription(UInt32, topics.RESETS, self._on_resets, qos.STATUS_QOS)
        if self.body is not None:
            self.create_subscription(JointState, topics.JOINT_STATES, self._on_joint_state, qos.STREAM_QOS)
            self.create_subscription(JointState, topics.PHASE, self._on_phase, qos.STREAM_QOS)
        self._publish(first_command(self.policy, self.desired_speed))  # the start: on the command
        self.get_logger().info(
            f"policy {self.policy.name}: {self.desired_speed:.2f} m/s; "
            f"send speeds on {self.resolve_topic_name(topics.CMD_SPEED)}"
        )


    def _flush_rejections(self) -> None:
        for line in self._rejections.flush():
            self.get_logger().warning(line)

    def _on_set_parameters(self, parameters: list) -> SetParametersResult:
        """``min_speed``/``max_speed`` at run time, validated as at start (the command in
        force is clamped into the new range); read-only ones are refused by rclpy."""
        low, high = self.min_speed, self.max_speed
        for param in parameters:
            if param.name not in ("min_speed", "max_speed"):
                continue
            try:
                value = finite(param.name, coerce(param.name, param.value, 0.0), *POLICY_PARAMS[param.name].range)
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
            low, high = (value, high) if param.name == "min_speed" else (low, value)
        if not low <= high:
            return SetParametersResult(successful=False,
                                       reason=f"min_speed ({low}) must not be above max_speed ({high})")
        self.min_speed, self.max_speed = low, high
        self.desired_speed = min(max(self.desired_speed, low), high)
        return SetParametersResult(successful=True)

    def _on_cmd_vel(self, msg: Twist) -> None:
        """``/cmd_vel``: linear.x is the commanded speed; RABBIT walks straight in its plane."""
        if not self._warned_planar and (msg.linear.y or msg.linear.z or msg.angular.x or msg.angular.y
                                        or msg.angular.z):
            self._warned_planar = True
            self.get_logger().warning(f"{self.resolve_topic_name(topics.CMD_VEL)}: RABBIT walks straight in its plane; "
                                      "only linear.x (the speed) is used, the other fields are ignored (said once)")
        self._command(msg.linear.x, self.resolve_topic_name(topics.CMD_VEL))

    def _on_resets(self, msg: UInt32) -> None:
        """The robot was placed again (a reset): a policy with memory starts afresh, as each
        walk of the ROS-free loop does (its first placement is the start: nothing to forget)."""
        if msg.data > 1 and msg.data != self._placements:
            reset_policy(self.policy)
            self._awaiting.clear()  # decisions of the walk before the placement
            if self.schedule is not None:  # the schedule starts over, from the start's command
                self.schedule.restart()
                self.desired_speed = self.initial_speed
        self._placements = msg.data

    def _on_cmd_speed(self, msg: Float64) -> None:
        if self._echoes and msg.data == self._echoes[0]:
            self._echoes.pop(0)  # a scheduled command this node published for the record, heard back
            return
        self._command(msg.data, self.resolve_topic_name(topics.CMD_SPEED))

    def _follow_schedule(self, stamp: int) -> None:
        """Command the scheduled speed that falls due at the state stamped ``stamp`` (ns),
        if any (:class:`~rabbit_policy.runtime.speed_schedule.SpeedSchedule`), and publish it
        on /cmd_speed for recordings and plots."""
        speed = self.schedule.due(stamp) if self.schedule is not None else None
        if speed is None:
            return
        self.get_logger().info(f"t = {stamp / 1e9:.3f} s: scheduled command {speed:.2f} m/s")
        self._command(speed, SCHEDULE_SOURCE)
        self._echoes.append(speed)
        self._speed_pub.publish(Float64(data=speed))

    def _command(self, value: float, topic: str) -> None:
        """A commanded speed (m/s) from ``topic``: clamped into range, rejected if not finite
        (each kind of line at most once a second: :class:`RejectionLog`)."""
        try:
            speed = clamp_speed(value, self.min_speed, self.max_speed)
        except ValueError as exc:
            self.rejected_commands += 1
            line = self._rejections.line(f"reject {topic}", f"rejected {topic}: {exc}; keeping "
                                                             f"{self.desired_speed:.2f} m/s")
            if line is not None:
                self.get_logger().error(line)
            return
        if speed != value:
            line = self._rejections.line(f"clamp {topic}", clamp_message(value, self.min_speed, self.max_speed, speed,
                                                                         topic))
            if line is not None:
                self.get_logger().warning(line)
        if speed != self.desired_speed and topic != SCHEDULE_SOURCE:  # (a scheduled one is logged with its time)
            line = self._rejections.line("command", f"commanded speed {speed:.2f} m/s")
            if line is not None:
                self.get_logger().info(line)
        self.desired_speed = speed

    def _on_hip_velocity(self, msg: TwistStamped) -> None:
        stamp = stamp_to_ns(msg.header.stamp)
        self._follow_schedule(stamp)
        try:
            due = self.clock.sample(stamp, msg.twist.linear.x, self.desired_speed)
        except ValueError as exc:
            self.get_logger().error(f"ignoring {self.resolve_topic_name(topics.HIP_VELOCITY)}: {exc}",
                                    throttle_duration_sec=1.0)
            return
        if self.body is None:
            for observation in due:
                self._decide(observation)
            return
        if self._awaiting and stamp < self._awaiting[-1][0]:
            self._awaiting.clear()  # placed again: those were the last walk's
        self._awaiting.extend((stamp, observation) for observation in due)
        self._decide_awaiting()

    def _on_joint_state(self, msg: JointState) -> None:
        """Body-state policies: torso pitch, its rate and the hip velocity of each state."""
        try:
            q, dq = joint_state_vectors(msg.name, msg.position, msg.velocity)
        except MessageError as exc:
            self.get_logger().error(f"ignoring {self.resolve_topic_name(topics.JOINT_STATES)}: {exc}",
                                    throttle_duration_sec=1.0)
            return
        self.body.add_state(stamp_to_ns(msg.header.stamp), q, dq)
        self._decide_awaiting()

    def _on_phase(self, msg: JointState) -> None:
        """Body-state policies: the controller's phase on each state it answered."""
        try:
            stamp, tau, rate = phase_from_msg(msg)
        except MessageError as exc:
            self.get_logger().error(f"ignoring {self.resolve_topic_name(topics.PHASE)}: {exc}",
                                    throttle_duration_sec=1.0)
            return
        self.body.add_phase(stamp, tau, rate)
        self._decide_awaiting()

    def _decide_awaiting(self) -> None:
        """Decide, in order, the due decisions whose body state is complete; one whose state
        or phase never comes (states ``horizon`` ticks newer are in) is given up, logged:
        the gait in force stays."""
        while self._awaiting:
            stamp, observation = self._awaiting[0]
            body = self.body.body_at(stamp)
            if body is None and not self.body.expired(stamp):
                return
            self._awaiting.popleft()
            if body is None:
                self.decisions_given_up += 1
                self.get_logger().error(
                    f"no body state for the decision at t = {stamp / 1e9:.3f} s (is the controller publishing "
                    f"{self.resolve_topic_name(topics.PHASE)}?); keeping the gait in force",
                    throttle_duration_sec=2.0)
                continue
            self._decide(replace(observation, body=body))

    def _on_step(self, msg: Header) -> None:
        stamp = stamp_to_ns(msg.stamp)  # the state before the switch; the loop decides on the one after
        self._follow_schedule(stamp + TICK_NS)
        for observation in self.clock.switch(stamp, self.desired_speed):
            self._decide(observation)

    def _decide(self, observation: Observation) -> None:
        self.last_observation = observation
        self._publish(self.policy.act(observation))

    def _publish(self, command: GaitCommand) -> None:
        """Publish a gait (alpha, Kd) and the initial state on it."""
        self._alpha_pub.publish(alpha_to_msg(command.alpha))
        self._kd_pub.publish(Float64(data=float(command.kd)))
        self.decisions += 1
        try:
            qpos, qvel = state_on_gait(command.alpha, self.initial_speed)
        except (ValueError, ZeroDivisionError) as exc:
            self.get_logger().error(f"no initial state on the gait just published: {exc}", throttle_duration_sec=5.0)
            return
        self._initial_state_pub.publish(JointState(name=list(JOINT_NAMES), position=qpos, velocity=qvel))


def main(args: list[str] | None = None) -> int:
    """Console script / ``ros2 run rabbit_policy policy_node``."""
    return run_node(lambda context: PolicyNode(context=context, solo_check=PROCESS_SOLO_CHECK), args)


if __name__ == "__main__":
    sys.exit(main())
