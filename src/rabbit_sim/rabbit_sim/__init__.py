"""RABBIT in MuJoCo: the packaged MJCF model (:mod:`.model`, with model options), the physics every
experiment steps (:mod:`.simulation`: ``Simulator``, fall and stall rules), the simulator
node (:mod:`.sim_node`) over its ROS-free stepping rules (:mod:`.stepping`), recording and
rendering. It knows no controller and no policy."""

import rabbit_msgs_py  # noqa: F401  (first: on a headless machine it picks MuJoCo's OpenGL backend, gl_backend)
