"""One ROS-free closed loop for every experiment: the simulator, the HZD controller and a
gait policy stepped together (:mod:`.loop`), what an experiment commands
(:mod:`.scenario`) and what it returns (:mod:`.result`)."""
