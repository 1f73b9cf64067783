"""Walk RABBIT in MuJoCo without ROS: a gait from the library, the HZD controller core,
the closed loop. Shared by ``scripts/walk.py``, the tests and the benchmarks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import mujoco

from rabbit_hzd_controller.controller import ControllerConfig, HZDController, Leg
from rabbit_hzd_controller.gait import Gait
from rabbit_hzd_controller.gait_state import state_on_gait
from rabbit_sim.model import load_model
from rabbit_sim.simulation import ClosedLoop, WalkResult


@dataclass(frozen=True)
class WalkSetup:
    """A closed loop ready to run, started on ``gait`` at its design speed, phase 0."""

    gait: Gait
    loop: ClosedLoop
    controller: HZDController


def loop_on_gait(model: mujoco.MjModel, alpha: Sequence[float], kd: float, speed: float,
                 kp: float | None = None) -> ClosedLoop:
    """A closed loop (HZD controller, left stance) placed at phase 0 of the gait ``alpha``
    (rad) moving forward at ``speed`` (m/s); ``kd`` in N m s/rad, ``kp`` in N m/rad
    (None: the controller's default)."""
    config = ControllerConfig() if kp is None else ControllerConfig(kp=kp)
    controller = HZDController(alpha, kd, config, Leg.LEFT)
    loop = ClosedLoop(model, controller)
    loop.reset(*state_on_gait(alpha, speed, config.geometry))
    return loop


def setup_walk(gait: Gait, model_variant: str = "paper") -> WalkSetup:
    """Build the model, controller and closed loop for ``gait``."""
    loop = loop_on_gait(load_model(model_variant), gait.alpha, gait.kd, gait.speed, gait.kp)
    return WalkSetup(gait=gait, loop=loop, controller=loop.controller)


def walk_gait(gait: Gait, duration: float, model_variant: str = "paper") -> WalkResult:
    """Walk ``gait`` for ``duration`` s of sim time and summarise (stops at a fall)."""
    return setup_walk(gait, model_variant).loop.run(duration)
