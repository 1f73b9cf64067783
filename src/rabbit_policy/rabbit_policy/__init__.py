"""Gait policies for RABBIT, by concern (importing this package imports nothing heavy; it
registers ``RabbitHZD-v0`` with Gymnasium when Gymnasium is imported, see :mod:`.registration`):

* :mod:`.runtime`: what ``policy_node`` runs: policies, the speed window, the network, the
  classic gait library.
* :mod:`.experiment`: the one ROS-free closed loop every experiment runs (simulator +
  HZD controller + gait policy), its scenarios (speed and push schedules, model options)
  and its result.
* :mod:`.gait_design`: the classic HZD gait library's optimizer and seed.
* :mod:`.learning`: the ``RabbitHZD-v0`` Gymnasium env, ES, PPO, the warm start and the
  training loop.
* :mod:`.evaluation`: the paper's section IV and beyond: experiments, acceptance, Poincaré
  stability, push recovery, figures, report.
* :mod:`.bringup`: starting the ROS 2 stack in place of a launch file.
"""

from .registration import register_when_gymnasium_is_imported

register_when_gymnasium_is_imported()
