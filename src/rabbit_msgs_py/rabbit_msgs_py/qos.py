"""QoS profiles of the rabbit-hzd topics (needs rclpy).

* State and command streams (1 kHz): reliable, keep last 10 — lockstep simulation counts
  on every torque arriving; depth 10 rides out short scheduling hiccups.
* Gait parameters (alpha, Kd): reliable, transient local, depth 1 — a controller started
  late still receives the gait currently in force.
* User commands (speed, push): reliable, keep last 10.
* Clock: reliable, keep last 1 (the newest time is the only one that matters).
"""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

STREAM_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
GAIT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
COMMAND_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
