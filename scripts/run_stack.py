#!/usr/bin/env python3
"""Run the RABBIT ROS 2 stack (simulator, HZD controller, policy) in place of a launch file.

    scripts/run_stack.py --speed 1.0 --duration 30
    scripts/run_stack.py --speed-schedule "0:0.8,10:1.2,20:1.0" --duration 30
    scripts/run_stack.py --speed 1.0 --duration 20 --push "5:60:0.1" --mode paced
    scripts/run_stack.py --speed 1.0 --duration 10 --in-process --json
    scripts/run_stack.py --speed 1.0 --duration 30 --record runs/walk1   # rosbag2 (MCAP) bag

By default the three nodes start as separate processes (``python -m <package>.<node>
--ros-args -p ...``, as ``ros2 run`` would) and this script supervises the run: it sends
the speed schedule on ``/cmd_speed`` at its sim times (the pushes are sim_node's
``push_schedule``, applied at their exact sim times), and at the end prints, per schedule segment, the commanded speed and the mean hip speed over
the segment's second half, the steps, whether RABBIT fell, and the real-time factor
(sim time / wall time). ``--in-process`` runs all nodes in this process on one
EventsExecutor instead (the fastest choice measured here; see README "Executors").
Ctrl-C stops the nodes cleanly and prints what was measured so far.

With ``--json``: one object, the same keys as ``walk.py --json`` for the same scenario
(``rabbit_policy.experiment.result.run_summary``: ``fell``, ``steps``, ``segments`` with
``mean_speed`` and ``reach_time``, ``real_time_factor``, ``completed``, ``error``, ...);
node logs go to stderr.
Exit status: 0 walked the whole run, 1 fell or stalled (no touchdown for 2 s), 2 bad arguments or another
stack already running in this ROS_DOMAIN_ID (they would cross-talk), 3 the run did not complete
(a node died, no progress, interrupted).
"""

import sys

from rabbit_policy.commands.run_stack import main

if __name__ == "__main__":
    sys.exit(main())
