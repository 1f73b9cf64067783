"""Topic and service names of the rabbit-hzd stack (ROS-free constants).

No node spells a topic by hand: they all import these. Names are relative, so a stack
started in a namespace (``run_stack.py --namespace rabbit2``, or ``--ros-args -r
__ns:=/rabbit2`` on each node) uses ``/rabbit2/joint_states`` and so on, and two robots run
side by side in one ROS domain; in the root namespace they resolve to ``/joint_states`` ...
(:func:`resolve`), the names the docs use. Remap with ``--ros-args -r`` as usual.
"""

JOINT_STATES = "joint_states"
"""sensor_msgs/JointState, all 7 model joints (``JOINT_NAMES``), sim_node at 1 kHz."""
HIP_VELOCITY = "hip_velocity"
"""geometry_msgs/TwistStamped, linear.x = forward hip speed (m/s), sim_node with every state
while anyone subscribes (1 kHz)."""
STATE_BATCH = "sim/state_batch"
"""std_msgs/Float64MultiArray, sim_node: every state it publishes on ``/joint_states``, in
batches of up to ``batch_ticks`` (``rabbit_msgs_py.conversions.state_batch_to_msg``: rows of
stamp ns, position, velocity, effort). A batch goes out at every multiple of ``batch_ticks``
ticks of sim time, on every state a policy decides on (the period ``/hzd/gait_timing``
announces, ``rabbit_msgs_py.decision_ticks.PeriodicDecisions``), on a state sent again, and
when the physics halts or pauses: so an observer that needs every state (the policy's
averages, run_stack's supervisor, a plot) takes 50 messages a second instead of 1000, and a
decision's last sample is never held back."""
CLOCK = "clock"
"""rosgraph_msgs/Clock, simulation time, sim_node: ``clock_rate`` times per s of sim time
(a state whose stamp is on that grid) while anyone subscribes."""
JOINT_TORQUES = "joint_torques"
"""sensor_msgs/JointState, the controller's reply to one ``/joint_states`` message: the
four ``ACTUATED_JOINTS`` with their torques (N m) in ``effort``, ``header.stamp`` = the
stamp of the state answered, ``header.frame_id`` = the controller instance's id."""
ALPHA = "hzd/alpha"
"""std_msgs/Float64MultiArray, 6 x 4 Bezier coefficients (rad), see conversions."""
KD = "hzd/kd"
"""std_msgs/Float64, derivative gain (N m s/rad)."""
GAIT_TIMING = "hzd/gait_timing"
"""std_msgs/String (transient local), published by the policy node: how its gaits are
meant to apply, ``next_step`` (decided once per step, for the next one) or ``at_once:N``
(decided every N ticks, applied when they arrive, blended in; a ``decision_sync``
controller holds its reply to each due state for that state's decision). The controller
follows it unless its ``gait_timing`` parameter says otherwise."""
CMD_SPEED = "cmd_speed"
"""std_msgs/Float64, desired forward speed (m/s)."""
CMD_VEL = "cmd_vel"
"""geometry_msgs/Twist, the usual velocity command (teleop_twist_keyboard, navigation):
``linear.x`` is the desired forward speed (m/s), as on ``/cmd_speed``; RABBIT walks
straight in its plane, so the other fields are ignored (policy_node warns once)."""
PUSH = "push"
"""geometry_msgs/Wrench on the torso (N, N m, world frame)."""
PUSH_APPLIED = "push_applied"
"""geometry_msgs/WrenchStamped, published by sim_node whenever the push on the torso
changes (a push starts, from ``/push`` or its ``push_schedule``, or ends: zeros);
``stamp`` = sim time, frame ``world``. Recordings show the pushes from it."""
FALLEN = "fallen"
"""std_msgs/Bool, true once the paper's limits (torso pitch, hip height) are left."""
STEP = "hzd/step"
"""std_msgs/Header, published by hzd_controller_node at each touchdown: ``stamp`` = sim time
of the state on which the stance switched, ``frame_id`` = the new stance foot
(``left_foot`` / ``right_foot``, the model's foot sites). The policy node evaluates its
policy on this event."""
PHASE = "hzd/phase"
"""sensor_msgs/JointState, hzd_controller_node with a torque reply while anyone subscribes
(each reply; when the policy announces a decision every N ticks, the reply to the state
before each decision, the one it reads): one joint ``gait_phase``, ``position`` = the phase tau of the step (0 at the
touchdown, 1 at the next; unitless), ``velocity`` = d tau/dt (1/s), ``header.stamp`` = the
stamp of the state it was computed on, ``frame_id`` = the stance foot. A policy reading the
body state inside the step (features ``body``) takes it from here."""
REFERENCE = "hzd/reference"
"""sensor_msgs/JointState, hzd_controller_node with ``reference_rate`` > 0 (off by default), on
the states answered that often per s of sim time: the four ``ACTUATED_JOINTS``, ``position``
= the desired outputs y_d (rad), ``velocity`` = dy_d/dt (rad/s) of the virtual constraints,
``header.stamp`` = the state's, ``frame_id`` = the stance foot."""
TRACKING_ERROR = "hzd/tracking_error"
"""sensor_msgs/JointState beside :data:`REFERENCE`: ``position`` = y - y_d (rad),
``velocity`` = dy/dt - dy_d/dt (rad/s), what the PD law acts on (torque = -Kp e - Kd de/dt
before saturation)."""

DECISIONS_LOST = "hzd/decisions_lost"
"""std_msgs/UInt32 (transient local), published by hzd_controller_node at its start and within
50 ms of every change: the times it found the policy not deciding since it started (a due
decision that timed out, or a silence; its stats_file's ``decisions_timed_out`` plus
``policy_silences``). ``run_stack --attach`` reports a hand-started stack's lost decisions
from it. Unsigned: a stranger can make a run look lost, never a lost one look complete."""

INITIAL_STATE = "sim/initial_state"
"""sensor_msgs/JointState (transient local), the 7 joints' positions and velocities the
simulator starts from and returns to on ``/sim/reset``: the state at phase 0 of the gait in
force, published by ``policy_node`` with every gait. The simulator knows no gait."""

RESETS = "sim/resets"
"""std_msgs/UInt32 (transient local): how many times sim_node has placed the robot (1 at the
start, +1 at every reset), published just before the placed state. The controller restarts
on it and answers the placed state even when it equals the last state it answered: a
reset is an event, not inferred from stamps or values."""

SIM_MODE = "sim/mode"
"""std_msgs/String (transient local), published once by sim_node: how it steps, ``lockstep``,
``paced`` (each state waits for its torque reply) or ``realtime`` (it steps on the wall
clock), then `` signed=<simulator id>:<tag>`` when the simulator has a pairing key
(``PairingKey.sign_settings``). A controller not told ``decision_sync`` follows it: in
lockstep and paced it holds the reply to a state the policy decides on until that decision
is in, as run_stack's does. A keyed controller takes only a signed one, and the first it
takes only: the mode never changes while a simulator runs."""
SIM_MODES = ("lockstep", "paced", "realtime")
"""The values of ``/sim/mode`` (sim_node's ``mode``)."""
REPLY_MODES = ("lockstep", "paced")
"""Modes that step once per torque reply (never without the torque for the state)."""

MARKERS = "rabbit/markers"
"""visualization_msgs/MarkerArray: RABBIT in 3D for RViz and Foxglove (sim_node, every
``1 / markers_rate`` s of sim time; frame ``world``, namespace ``rabbit``): torso, femurs and
tibias as cylinders, feet as spheres (larger and yellow on the ground), a ground plate, the
push acting now as a red arrow. See ``rabbit_sim.stepping.markers``."""

ROBOT_DESCRIPTION = "robot_description"
"""std_msgs/String (transient local), published once by sim_node: the URDF of the model it
simulates (``rabbit_sim.urdf``; links, masses, joints named as in ``/joint_states``), as
robot_state_publisher publishes it, for RViz's RobotModel and Foxglove's URDF layer."""

RECORDED_UNTIL = "recorder/recorded_until"
"""rosgraph_msgs/Clock (transient local): the header stamp (sim time) of the newest
``/joint_states`` message recorder_node has written, after each; a negative stamp first
(the recorder announces itself before it subscribes). In lockstep and paced modes sim_node
steps only while the recorder is at most a few states behind, so under any load no message
is lost: from the start with ``wait_for_recorder`` (run_stack), else from a recorder's first
report until it leaves (one started by hand). run_stack stops the nodes of a recorded run
only once it reaches the run's last state, so the bag ends with the run."""

RESET_SERVICE = "sim/reset"
"""std_srvs/Trigger: put the robot back in the newest ``/sim/initial_state`` at t = 0."""
PAUSE_SERVICE = "sim/pause"
"""std_srvs/SetBool: data=true pauses the physics, false resumes."""
RELEASE_CONTROLLER_SERVICE = "sim/release_controller"
"""std_srvs/Trigger: a simulator without a pairing key forgets the controller it takes
torques from; the next controller to answer is paired (logged). With a key it refuses: a
controller started with the stack's key is paired when it answers (``rabbit_msgs_py.pairing``)."""


def resolve(name: str, namespace: str = "/") -> str:
    """The fully qualified name of a stack topic or service in ``namespace``:
    ``resolve(JOINT_STATES)`` = ``/joint_states``, ``resolve(JOINT_STATES, "/rabbit2")`` =
    ``/rabbit2/joint_states``."""
    return f"{namespace.rstrip('/')}/{name.lstrip('/')}"
