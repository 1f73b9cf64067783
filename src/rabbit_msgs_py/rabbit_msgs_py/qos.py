"""QoS profiles of the rabbit-hzd topics (needs rclpy).

* State and torque streams (1 kHz): reliable, keep last 10 — lockstep simulation counts
  on every torque arriving; depth 10 rides out short scheduling hiccups.
* Hip velocity (1 kHz): reliable, keep last 250 — the policy averages the last 200
  samples at every step and must not lose one while it is busy.
* State batches (``/sim/state_batch``, about 50 Hz): reliable, keep last 100 (2 s): the
  policy averages every state and must not lose one.
* Gait parameters (alpha, Kd, gait timing): reliable, transient local, depth 1 — a
  controller started late still receives the gait currently in force. The controller and
  the simulator read them with depth 100,000 (``GAIT_READER_QOS``; nothing is allocated
  until messages wait): a flood of unsigned gaits pushes the policy's signed one out of a
  reader that is not taken in time, and a stack kept from its first gait never starts. A
  10 kHz flood that began before the controller filled 5,400 messages between its reader's
  creation and its first take (depth 1000: the policy's first gait lost, the stack never
  started; docs/faults.md); 100,000 is 10 s of such a flood.
* User commands (speed, push): reliable, keep last 10.
* Status (``/fallen``): reliable, transient local, depth 1 — a late subscriber learns
  the current state.
* Events (``/hzd/step``): reliable, keep last 10.
* Torque replies and touchdowns: the stream and event profiles, and hzd_controller_node's
  publishers declare a liveliness lease of 1 s (``TORQUE_QOS``, ``STEP_QOS``: its DDS
  participant asserts it, whatever the Python thread does), so sim_node can tell a stopped
  or killed controller from a busy one: a second subscription to ``/hzd/step`` (a few
  messages a second, not the 1 kHz replies) asks for that lease
  (``LIVELINESS_MONITOR_QOS``) and matches only the controllers' writers. Subscribers with
  the default profile stay compatible.
* Services (``/sim/reset``, ``/sim/pause``, ``/sim/release_controller``): depth 1000 on both
  sides (``SERVICE_QOS``). The server keeps every request; but a caller's responses land in
  its own client's history, and rclpy's default client keeps 10: a client that makes more
  than 10 calls before it takes their answers loses the rest, and no server can make up
  for that (docs/faults.md measures it). Make such clients with it.
* Clock: reliable, keep last 10 (a recorder in lockstep must get every one; the newest
  is the one that matters to anyone else).
"""

from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy


def _reliable(depth: int, durability: DurabilityPolicy = DurabilityPolicy.VOLATILE) -> QoSProfile:
    """A reliable keep-last profile of ``depth``."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=durability,
    )


STREAM_QOS = _reliable(10)
HIP_VELOCITY_QOS = _reliable(250)
BATCH_QOS = _reliable(100)
GAIT_QOS = _reliable(1, DurabilityPolicy.TRANSIENT_LOCAL)
GAIT_READER_QOS = _reliable(100_000, DurabilityPolicy.TRANSIENT_LOCAL)
STATUS_QOS = _reliable(1, DurabilityPolicy.TRANSIENT_LOCAL)
COMMAND_QOS = _reliable(10)
EVENT_QOS = _reliable(10)
CLOCK_QOS = _reliable(10)
MARKERS_QOS = _reliable(10)

LIVELINESS_LEASE_S = 1
"""s: a controller's torque publisher asserts its liveliness at least this often."""
TORQUE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                        liveliness=LivelinessPolicy.AUTOMATIC,
                        liveliness_lease_duration=Duration(seconds=LIVELINESS_LEASE_S))
STEP_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      liveliness=LivelinessPolicy.AUTOMATIC,
                      liveliness_lease_duration=Duration(seconds=LIVELINESS_LEASE_S))
"""``/hzd/step``: the event profile with the controller's liveliness lease."""
LIVELINESS_MONITOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                                    reliability=ReliabilityPolicy.BEST_EFFORT,
                                    liveliness=LivelinessPolicy.AUTOMATIC,
                                    liveliness_lease_duration=Duration(seconds=2 * LIVELINESS_LEASE_S))
"""Requests a lease: matches only publishers that declare one (TORQUE_QOS), best effort and
depth 1, read raw (its messages are not needed, only its liveliness events)."""
SERVICE_QOS = QoSProfile(depth=1000)
"""Services and their clients: see the module docstring."""
