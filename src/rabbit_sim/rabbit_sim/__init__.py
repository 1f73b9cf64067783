"""RABBIT in MuJoCo: the packaged MJCF model (:mod:`.model`), the ROS-free closed loop
(:mod:`.simulation`) and, on top, the simulator node."""
