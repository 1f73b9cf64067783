"""Bring-up of the ROS 2 stack in place of a launch file: what to run (:mod:`.stack`'s
``StackConfig``), the supervising experiment node, in-process and multi-process runs."""
