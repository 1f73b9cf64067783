"""The command lines a ROS install runs with ``ros2 run rabbit_policy <name>`` (``walk``,
``run_stack``, ``set_speed``); ``scripts/<name>.py`` in a clone runs the same ``main``."""
