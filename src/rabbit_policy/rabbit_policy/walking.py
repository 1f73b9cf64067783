"""Walk RABBIT in MuJoCo without ROS: a gait from the library, the HZD controller core,
the closed loop. Shared by ``scripts/walk.py``, the tests and the benchmarks."""

from __future__ import annotations

from dataclasses import dataclass

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


def setup_walk(gait: Gait, model_variant: str = "paper") -> WalkSetup:
    """Build the model, controller and closed loop for ``gait``."""
    model = load_model(model_variant)
    controller = HZDController(gait.alpha, gait.kd, ControllerConfig(kp=gait.kp), Leg.LEFT)
    loop = ClosedLoop(model, controller)
    qpos, qvel = state_on_gait(gait.alpha, gait.speed, controller.config.geometry)
    loop.reset(qpos, qvel)
    return WalkSetup(gait=gait, loop=loop, controller=controller)


def walk_gait(gait: Gait, duration: float, model_variant: str = "paper") -> WalkResult:
    """Walk ``gait`` for ``duration`` s of sim time and summarise (stops at a fall)."""
    return setup_walk(gait, model_variant).loop.run(duration)
