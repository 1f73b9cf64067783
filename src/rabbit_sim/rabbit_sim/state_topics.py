"""The topics a simulated state goes out on (needs rclpy): :class:`StateTopics`.

``/joint_states`` with every state (the controller's input, 1 kHz); the same state into the
next ``/sim/state_batch`` (sent when :class:`~rabbit_sim.stepping.batch.StateBatcher` says:
the observers' stream); ``/hip_velocity`` (world frame: x forward, z up, pitch rate) with every
state and ``/clock`` on the states of its ``clock_rate`` grid, each only while anyone
subscribes (an unread 1 kHz stream costs every process on the machine).
"""

from __future__ import annotations

from geometry_msgs.msg import TwistStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header, UInt32

from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.cdr import JointStateWriter
from rabbit_msgs_py.conversions import BATCH_DIMENSIONS, stamp_from_ns, state_batch_to_msg
from rabbit_msgs_py.decision_ticks import TICK_NS
from rabbit_msgs_py.joints import JOINT_NAMES
from rabbit_msgs_py.pairing import PairingKey

from .stepping import State
from .stepping.batch import StateBatcher


class StateTopics:
    """Publishers of a node for its states; ``batch_ticks`` and ``clock_ticks`` as in
    :class:`~rabbit_sim.stepping.settings.SimSettings`. With a pairing ``key`` every batch is signed by
    simulator instance ``source``, counted from 1 (``PairingKey.batch_label``): keyed
    observers take no other."""

    def __init__(self, node, batch_ticks: int, clock_ticks: int, key: PairingKey | None = None,
                 source: str = "") -> None:
        pub = node.create_publisher
        self._state_pub = pub(JointState, topics.JOINT_STATES, qos.STREAM_QOS)
        self._batch_pub = pub(Float64MultiArray, topics.STATE_BATCH, qos.BATCH_QOS)
        self._hip_pub = pub(TwistStamped, topics.HIP_VELOCITY, qos.HIP_VELOCITY_QOS)
        self._clock_pub = pub(Clock, topics.CLOCK, qos.CLOCK_QOS)
        self._resets_pub = pub(UInt32, topics.RESETS, qos.STATUS_QOS)
        self.placement = 0  # the robot's placements so far (signed into every state)
        self.batcher = StateBatcher(batch_ticks)
        self._clock_every = clock_ticks * TICK_NS  # ns of sim time between /clock messages
        self._joint_states = JointStateWriter(JOINT_NAMES)  # serialized: no message object per tick
        self._hip_msg = TwistStamped(header=Header(frame_id="world"))
        self._key, self._source, self.batches_sent = key, source, 0

    def placed(self, count: int) -> None:
        """The robot was placed for the ``count``-th time: ``/sim/resets``, and the count every
        state signs from now on."""
        self.placement = count
        self._resets_pub.publish(UInt32(data=count))

    def publish(self, state: State) -> None:
        """One state on every topic that takes it now."""
        # keyed: signed with its placement (frame_id, PairingKey.sign_state): a keyed controller takes no other
        # node's states, and no state of this one's again after a later one (a replay)
        signed = (self._key.sign_state(self._source, self.placement, state.stamp, state.qpos, state.qvel)
                  if self._key is not None else "")
        self._state_pub.publish(self._joint_states.bytes(state.stamp, signed, state.qpos, state.qvel, state.effort))
        if self.batcher.add(state.stamp, state.qpos, state.qvel, state.effort):
            self.send_batch()
        if self._hip_pub.get_subscription_count():
            hip = self._hip_msg
            hip.header.stamp = stamp_from_ns(state.stamp)
            hip.twist.linear.x, hip.twist.linear.z, hip.twist.angular.y = state.qvel[0], state.qvel[1], state.qvel[2]
            self._hip_pub.publish(hip)
        if state.stamp % self._clock_every == 0 and self._clock_pub.get_subscription_count():
            self._clock_pub.publish(Clock(clock=stamp_from_ns(state.stamp)))

    def send_batch(self) -> None:
        """The states not yet batched, now (nothing if there are none)."""
        if self.batcher.count:
            rows, count = self.batcher.take()
            self.batches_sent += 1
            label = (self._key.batch_label(self._source, self.batches_sent, rows.tobytes()) if self._key is not None
                     else BATCH_DIMENSIONS[0])
            self._batch_pub.publish(state_batch_to_msg(rows, count, label))
