"""Bring-up of the whole stack in place of a launch file (used by ``scripts/run_stack.py``,
``scripts/bench_stack.py`` and the tests), one job per module (import each from its module):

* :mod:`.config`: :class:`StackConfig` says what to run (``scripts/run_stack.py``'s
  options; :mod:`rabbit_policy.experiment.scenario` parses its ``--speed-schedule`` and
  ``--push``), and the node parameters and ``--ros-args`` it makes.
* :mod:`.supervisor`: the experiment node. It publishes ``/cmd_speed`` as the schedule says
  (at the first state it sees at or after each change, as the closed loop steps it),
  counts touchdowns (``/hzd/step``), watches ``/fallen``, detects a stall (no touchdown for
  ``stall_after`` s of sim time), and builds the fast path's ``WalkResult`` from the states
  and touchdowns it saw, so a run's report is the fast path's (:class:`RunReport`, the
  same JSON as ``walk.py --json``). It takes every state from the simulator's batches
  (``/sim/state_batch``, about 50 messages a second), so it takes nothing at 1 kHz and
  sees every state the fast path sees.
* Pushes are not sent by the supervisor but given to ``sim_node`` as its
  ``push_schedule`` parameter: the simulator applies them at their exact sim times, as
  the fast path does, so a push experiment repeats exactly whatever the load.
* :mod:`.in_process`: :func:`run_in_process` spins policy, controller, simulator and
  supervisor on one executor; :mod:`.processes`: :func:`run_multi_process` starts the
  nodes as separate processes (``python -m <module> --ros-args ...``, exactly what
  ``ros2 run`` executes) and runs the supervisor here.
* :mod:`.probe`: :func:`other_stack` finds another stack in this ROS domain.
"""
