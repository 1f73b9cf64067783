#!/usr/bin/env python3
"""Walk RABBIT in MuJoCo without ROS: the one experiment command.

    scripts/walk.py --controller classic --speed 1.0 --duration 60
    scripts/walk.py --controller learned --speed-schedule "0:0.8,10:1.2,20:0.9" --duration 30 --json
    scripts/walk.py --controller learned --speed 1.0 --push "3:-100:0.1" --friction 0.4 --json
    scripts/walk.py --controller classic --speed 1.2 --model drives --torque-delay 0.005
    scripts/walk.py --controller recovery --speed 1.0 --push "3.875:-180:0.1" --duration 8 --video walk.gif

``--controller classic`` is classic HZD (the packaged gait library: the calibrated blend
that walks at the command, or ``--library-mode nearest``); ``--controller learned`` is
HZD-RL (the shipped policy or ``--policy-file``); ``--controller recovery`` is classic plus
the model-based push-recovery rule (``rabbit_policy.runtime.recovery``). Each picks alpha
and Kd as ``policy_node`` does (classic and recovery every 20 ticks, learned as trained;
``--decision-period`` overrides), on the closed loop every experiment runs
(``rabbit_policy.experiment.loop``). ``hzd`` and ``rl`` are accepted as aliases.

The robot starts on the gait for the first commanded speed, moving at it. Pushes are
``T:FX:DUR`` (sim time s, force N along world x on the torso, duration s). Model errors:
``--model drives`` (the real robot's gears and joint friction), ``--friction`` (foot
friction coefficient, 0.8 by default), ``--torso-mass-scale``, ``--torque-delay`` (s).
``--video FILE.gif``: the walk as an animated GIF (offscreen, 25 frames per s of sim time,
320 x 240; on a machine without a display MuJoCo's EGL or OSMesa backend is chosen by itself).

``--json`` prints one object, always with the same keys: ``fell``, ``stalled``,
``fall_time``, ``stall_time``, ``duration``, ``steps``, ``mean_speed`` (m/s, last half;
null after a fall or stall), ``peak_torque`` (N m), ``rejected``, ``touchdowns`` (sim
times, s), ``segments`` (``command``, ``start``, ``end``, ``mean_speed`` over the
segment's second half, ``reach_time``: s from the change to the end of the first whole
step within ``--tolerance`` of the command, or null), plus ``controller``, ``policy``,
``scenario``, ``real_time_factor``, ``wall_time`` (s), ``completed`` and ``error``. No NaN:
null instead.
Exit status: 0 walked, 1 fell or stalled, 2 bad arguments or no policy.
"""

import sys

from rabbit_policy.commands.walk import main

if __name__ == "__main__":
    sys.exit(main())
