"""What every rabbit-hzd node shares: joint orders, topic names, QoS profiles and message
conversions. Modules that need rclpy import it themselves; :mod:`.joints` is ROS-free.

Importing it on a headless machine picks MuJoCo's offscreen OpenGL backend unless ``MUJOCO_GL``
is set (:func:`.gl_backend.choose_gl_when_headless`): MuJoCo reads that variable once, at its own
import, and its default (GLFW) needs a display. Every package of ours imports this one before
mujoco."""

from .gl_backend import choose_gl_when_headless
from .joints import ACTUATED_JOINTS, JOINT_NAMES, N_ACTUATED, N_JOINTS

choose_gl_when_headless()

__all__ = ["ACTUATED_JOINTS", "JOINT_NAMES", "N_ACTUATED", "N_JOINTS"]
