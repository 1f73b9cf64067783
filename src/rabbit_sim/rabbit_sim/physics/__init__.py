"""RABBIT's physics, ROS-free: the MuJoCo model and its variants (:mod:`.model`), one simulation
step with pushes, torque delay and the fall and stall rules (:mod:`.simulation`), and the
compiled kernels every path shares (:mod:`.compiled`). Imports nothing else of rabbit_sim: the
stepping core and the nodes are built on it."""
