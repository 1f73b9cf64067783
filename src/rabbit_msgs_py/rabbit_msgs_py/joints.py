"""Joint names and orders shared by every package (ROS-free).

``JOINT_NAMES`` is the order of the 7 model joints in MuJoCo ``qpos``/``qvel``, in
``/joint_states`` and in the controller's state vectors: the planar floating base
(``x``, ``z``: world position of the hip in m; ``torso_pitch``: rad, + leaning forward)
then the four actuated joints (rad, + = flexion). ``ACTUATED_JOINTS`` is the order of the
four joint torques (N m) in ``/joint_torques`` and in MuJoCo ``ctrl``: the ros2_control
effort-command convention of one value per joint in a fixed, documented order.
"""

JOINT_NAMES: tuple[str, ...] = (
    "x",
    "z",
    "torso_pitch",
    "left_hip",
    "left_knee",
    "right_hip",
    "right_knee",
)
ACTUATED_JOINTS: tuple[str, ...] = JOINT_NAMES[3:]
N_JOINTS = len(JOINT_NAMES)
N_ACTUATED = len(ACTUATED_JOINTS)
