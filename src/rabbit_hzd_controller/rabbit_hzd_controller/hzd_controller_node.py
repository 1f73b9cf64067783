"""``hzd_controller_node``: the HZD PD controller as a ROS 2 node (1 kHz, one torque
command per state).

Subscribes ``/joint_states`` and the gait (``/hzd/alpha``, ``/hzd/kd``, transient local, so a
controller started late gets the gait in force); publishes on ``/joint_torques`` one reply
per distinct state (sensor_msgs/JointState: the four ``ACTUATED_JOINTS`` and their torques
in ``effort``, ``header.stamp`` = the stamp of the state answered, ``header.frame_id`` = this
controller instance's id, :attr:`HZDControllerNode.source`) and ``/hzd/step`` at each
touchdown.
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
    short,
    stamp_to_ns,
    torques_to_msg,
)
from rabbit_msgs_py.parameters import Param, coerce, declare
from rabbit_msgs_py.runtime import NodeStartError, run_node

from .controller import ControllerConfig, HZDController, Leg, infer_stance, validate_alpha, validate_kd

FOOT_FRAMES = {Leg.LEFT: "left_foot", Leg.RIGHT: "right_foot"}


_DEFAULTS = ControllerConfig()
CONTROLLER_PARAMS = {
    "kp": Param(_DEFAULTS.kp, "proportional gain of the PD law, N m/rad, finite > 0", dynamic=True),
    "torque_limit": Param(_DEFAULTS.torque_limit, "torque saturation, N m, finite > 0 (RABBIT: 150)"),
    "touchdown_min_phase": Param(_DEFAULTS.touchdown_min_phase,
                                 "phase the swing foot must pass before a touchdown counts, in (0, 1)"),
    "max_kd": Param(_DEFAULTS.max_kd, "largest Kd accepted on /hzd/kd, N m s/rad, finite > 0", dynamic=True),
    "blend_phase": Param(_DEFAULTS.blend_phase, "blend a new gait in over this much phase after a touchdown "
                                                "that brings it, in [0, 1] (0 = off)", dynamic=True),
    "within_step_blend": Param(_DEFAULTS.within_step_blend, "gait_timing at_once: blend a new gait in over "
                                                            "this much phase, in (0, 1]", dynamic=True),
    "within_step_until": Param(_DEFAULTS.within_step_until, "gait_timing at_once: a gait arriving at or after "
                                                            "this phase waits for the next touchdown, in (0, 1]",
                               dynamic=True),
}
GAIT_TIMINGS = ("next_step", "at_once")
NODE_PARAMS = {
    "gait_timing": Param("policy", "when a new gait applies: policy (as /hzd/gait_timing says; next_step until "
                                   "it does), next_step (queued to the next touchdown) or at_once (blended in "
                                   "within the step)"),
}


class HZDControllerNode(Node):
    """Parameters: :data:`CONTROLLER_PARAMS` (``kp``, ``max_kd``, ``blend_phase`` and
    ``within_step_blend`` may change at run time; the rest are read-only) and
    :data:`NODE_PARAMS`."""

    def __init__(self, context=None, **overrides) -> None:
        super().__init__("hzd_controller_node", context=context)
        values = declare(self, {**CONTROLLER_PARAMS, **NODE_PARAMS}, overrides)
        self.follow_policy_timing = values.pop("gait_timing") == "policy"
        self.gait_timing = "next_step" if self.follow_policy_timing else self.get_parameter("gait_timing").value
        try:
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

        self.source = controller_id(self.get_name())  # this instance, in every reply's frame_id
        self._torque_msg = torques_to_msg([0.0] * 4, source=self.source)  # names once; effort, stamp per tick
        self._torque_pub = self.create_publisher(JointState, topics.JOINT_TORQUES, qos.STREAM_QOS)
        self._step_pub = self.create_publisher(Header, topics.STEP, qos.EVENT_QOS)
        self.create_subscription(JointState, topics.JOINT_STATES, self._on_state, qos.STREAM_QOS)
        self.create_subscription(Float64MultiArray, topics.ALPHA, self._on_alpha, qos.GAIT_QOS)
        self.create_subscription(Float64, topics.KD, self._on_kd, qos.GAIT_QOS)
        self.create_subscription(String, topics.GAIT_TIMING, self._on_gait_timing, qos.GAIT_QOS)
        self.create_subscription(UInt32, topics.RESETS, self._on_resets, qos.STATUS_QOS)
        self.get_logger().info(f"HZD controller {self.source} (Kp = {self.config.kp:.0f} N m/rad) waiting for a gait")

    def _on_set_parameters(self, parameters: list) -> SetParametersResult:
        """``kp``, ``max_kd``, ``blend_phase`` at run time, validated as at start (read-only
        ones are refused by rclpy before this is called)."""
        changes = {}
        for param in parameters:
            if param.name not in CONTROLLER_PARAMS:
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
            self.get_logger().error(f"rejected {topics.ALPHA}: {short(str(exc), 200)}; keeping the last good gait")
            return
        self._alpha = alpha
        if self.controller is not None:
            if self.gait_timing == "at_once":
                self.controller.apply_now(tuple(alpha))
            else:
                self.controller.set_alpha(alpha)
        self._answer_waiting_state()

    def _on_gait_timing(self, msg: String) -> None:
        if not self.follow_policy_timing or msg.data == self.gait_timing:
            return
        if msg.data not in GAIT_TIMINGS:
            self.get_logger().error(f"rejected {topics.GAIT_TIMING} {short(repr(msg.data), 60)}: not one of {GAIT_TIMINGS}; "
                                    f"keeping {self.gait_timing}")
            return
        self.gait_timing = msg.data
        self.get_logger().info(f"gaits apply {'when they arrive, blended in' if msg.data == 'at_once' else 'at the next touchdown'}")

    def _on_kd(self, msg: Float64) -> None:
        try:
            kd = validate_kd(msg.data, self.config)
        except ValueError as exc:
            self.rejected_gaits += 1
            self.get_logger().error(f"rejected {topics.KD}: {short(str(exc), 200)}; keeping the last good value")
            return
        self._kd = kd
        if self.controller is not None:
            if self.gait_timing == "at_once":
                self.controller.set_kd(kd)
            else:
                self.controller.queue_kd(kd)
        self._answer_waiting_state()

    def _on_resets(self, msg: UInt32) -> None:
        first = self._resets is None
        if msg.data == self._resets:
            return
        self._resets = msg.data
        if first:
            return  # the count in force when this node started: nothing to restart
        self._restart = True
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
        if self._waiting_state is not None and self._alpha is not None and self._kd is not None:
            msg, self._waiting_state = self._waiting_state, None
            self._on_state(msg)

    # -------------------------------------------------------------- state
    def _on_state(self, msg: JointState) -> None:
        try:
            q, dq = joint_state_vectors(msg.name, msg.position, msg.velocity)
        except MessageError as exc:
            self.rejected_states += 1
            self.get_logger().error(f"ignoring malformed {topics.JOINT_STATES}: {exc}", throttle_duration_sec=1.0)
            return
        self.states_received += 1
        stamp = stamp_to_ns(msg.header.stamp)
        if stamp == self._last_stamp and (q, dq) == self._last_state:
            self._dropped = msg
            self._torque_pub.publish(self._torque_msg)  # a re-send: the same reply again
            self.replies_repeated += 1
            return
        if self._alpha is None or self._kd is None:
            self._waiting_state = msg
            self.get_logger().warning(
                f"no gait yet (waiting for {topics.ALPHA} and {topics.KD}); the state will be answered once it is "
                "complete",
                throttle_duration_sec=2.0,
            )
            return
        controller = self.controller
        if controller is None or self._restart or stamp < self._last_stamp:
            stance = infer_stance(q, self.config.geometry)
            if controller is None:
                controller = self.controller = HZDController(self._alpha, self._kd, self.config, stance)
            else:
                controller.reset(self._alpha, self._kd, stance)
                self.get_logger().info("simulation reset: controller restarted on the gait")
            self._restart = False
        self._dropped = None
        torques = controller.compute(q, dq)
        self._last_stamp = stamp
        self._last_state = (q, dq)
        torque_msg = self._torque_msg
        torque_msg.header.stamp = msg.header.stamp
        torque_msg.effort = torques
        self._torque_pub.publish(torque_msg)
        self.torques_published += 1
        if controller.touchdown:
            self._step_pub.publish(Header(stamp=msg.header.stamp, frame_id=FOOT_FRAMES[controller.stance]))


def main(args: list[str] | None = None) -> int:
    """Console script / ``ros2 run rabbit_hzd_controller hzd_controller_node``."""
    return run_node(HZDControllerNode, args)


if __name__ == "__main__":
    sys.exit(main())
