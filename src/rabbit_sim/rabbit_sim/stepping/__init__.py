"""How ``sim_node`` steps, without ROS: :mod:`.rules` (lockstep bookkeeping and its pacing,
realtime pacing, the torque watchdog, recorder flow control, run statistics) and
:mod:`.driver` (:class:`SimDriver`: the simulator driven by those rules, taking the node's
events and returning what to publish and log). Every rule is unit-tested without rclpy."""

from .driver import Fallen, Frame, Log, Markers, Placed, PushApplied, SimDriver, State
from .rules import (
    Admit,
    ControllerPairing,
    FOLLOW_PATIENCE,
    RECORDER_LAG,
    RECORDER_RESEND,
    REPLY_GRACE,
    SILENCE_WARNING_AFTER,
    Lateness,
    LatenessMonitor,
    Lockstep,
    Pacer,
    RealtimeClock,
    RecorderGate,
    Reply,
    TickStatistics,
    TorquePublishers,
    Watchdog,
    WatchdogEvent,
    silence_cause,
)

__all__ = [
    "FOLLOW_PATIENCE", "RECORDER_LAG", "RECORDER_RESEND", "REPLY_GRACE", "SILENCE_WARNING_AFTER", "Admit", "ControllerPairing", "Fallen", "Frame", "Lateness",
    "LatenessMonitor", "Lockstep", "Log", "Markers", "Pacer", "Placed", "PushApplied", "RealtimeClock",
    "RecorderGate", "Reply", "SimDriver", "State", "TickStatistics", "TorquePublishers", "Watchdog", "WatchdogEvent",
    "silence_cause",
]
