"""What every rabbit-hzd node shares: joint orders, topic names, QoS profiles and message
conversions. Modules that need rclpy import it themselves; :mod:`.joints` is ROS-free."""

from .joints import ACTUATED_JOINTS, JOINT_NAMES, N_ACTUATED, N_JOINTS

__all__ = ["ACTUATED_JOINTS", "JOINT_NAMES", "N_ACTUATED", "N_JOINTS"]
