"""ROS-free closed loop: the RABBIT MuJoCo model driven by the HZD controller core.

This is the fast path used by ``scripts/walk.py``, the gait optimizer, the Gymnasium
environment, tests and benchmarks; ``sim_node`` steps the same model the same way.
One physics step (1 ms) = one control tick.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol, Sequence

import mujoco
import numpy as np


class Controller(Protocol):
    """What the loop needs from a controller (``HZDController`` satisfies it)."""

    steps: int
    touchdown: bool

    def compute(self, q: Sequence[float], dq: Sequence[float]) -> list[float]: ...


@dataclass(frozen=True)
class FallLimits:
    """The paper's episode limits: |torso pitch| < 0.5 rad and 0.6 m < hip height < 0.8 m.

    ``max_hip_height`` gets a small tolerance above the paper's 0.8 m because a straight
    vertical leg puts the hip at exactly 0.8 m (less the ~0.1 mm contact penetration)."""

    max_abs_pitch: float = 0.5
    min_hip_height: float = 0.6
    max_hip_height: float = 0.8 + 1e-3

    def fallen(self, hip_height: float, pitch: float) -> bool:
        return (
            abs(pitch) >= self.max_abs_pitch
            or hip_height <= self.min_hip_height
            or hip_height >= self.max_hip_height
        )


@dataclass
class Touchdown:
    """One stance switch: sim time (s), new stance foot x (m), hip x (m)."""

    time: float
    foot_x: float
    hip_x: float


@dataclass
class WalkResult:
    """Summary of a walk. Speeds in m/s, lengths in m, times in s, torques in N m."""

    fell: bool
    fall_time: float | None
    duration: float
    steps: int
    mean_speed: float
    step_length: float
    step_period: float
    peak_torque: float
    touchdowns: list[Touchdown] = field(default_factory=list, repr=False)

    def summary(self) -> dict[str, float | int | bool | None]:
        return {
            "fell": self.fell,
            "fall_time": self.fall_time,
            "duration": self.duration,
            "steps": self.steps,
            "mean_speed": self.mean_speed,
            "step_length": self.step_length,
            "step_period": self.step_period,
            "peak_torque": self.peak_torque,
        }


class Simulator:
    """The RABBIT model stepped with given joint torques (no controller inside).

    One :meth:`step` applies four torques (N m, ``ACTUATED_JOINTS`` order, clipped by the
    actuators to +-150 N m) and advances one model timestep (1 ms). External pushes are a
    wrench on the torso (world frame) held for a duration. ``sim_node`` and
    :class:`ClosedLoop` both step through this class, so a ROS run and a ROS-free run of
    the same controller produce the same numbers.
    """

    def __init__(self, model: mujoco.MjModel, limits: FallLimits | None = None) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        self.limits = limits or FallLimits()
        self._torso = model.body("torso").id
        self._push_until = -1.0

    @property
    def time(self) -> float:
        """Simulation time (s)."""
        return float(self.data.time)

    @property
    def timestep(self) -> float:
        """Model timestep (s)."""
        return float(self.model.opt.timestep)

    def reset(self, qpos: Sequence[float], qvel: Sequence[float]) -> None:
        """Set the state (``JOINT_NAMES`` order) at t = 0 and zero controls and pushes."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:] = qpos
        self.data.qvel[:] = qvel
        self._push_until = -1.0
        mujoco.mj_forward(self.model, self.data)

    @property
    def push_wrench(self) -> tuple[float, float, float]:
        """The push acting now: (force x N, force z N, torque y N m), world frame; zeros
        when none."""
        wrench = self.data.xfrc_applied[self._torso]
        return float(wrench[0]), float(wrench[2]), float(wrench[4])

    def push(self, force_x: float, duration: float, force_z: float = 0.0, torque_y: float = 0.0) -> None:
        """Apply a wrench at the torso CoM, world frame (N, N, N m), for ``duration`` s
        from now (``round(duration / timestep)`` steps). Replaces a push still in progress."""
        wrench = self.data.xfrc_applied[self._torso]
        wrench[:] = 0.0
        wrench[0] = force_x
        wrench[2] = force_z
        wrench[4] = torque_y
        self._push_until = self.data.time + duration

    def step(self, torques: Sequence[float]) -> None:
        """Apply ``torques`` (N m) for one timestep and advance the physics."""
        data = self.data
        data.ctrl[:] = torques
        mujoco.mj_step(self.model, data)
        # half a step of tolerance: sim time sums 1 ms steps and drifts below exact values
        if self._push_until >= 0.0 and data.time >= self._push_until - 0.5 * self.model.opt.timestep:
            data.xfrc_applied[self._torso, :] = 0.0
            self._push_until = -1.0

    def fallen(self) -> bool:
        """True when the paper's limits (torso pitch, hip height) are left."""
        qpos = self.data.qpos
        return self.limits.fallen(qpos[1], qpos[2])


class ClosedLoop:
    """MuJoCo model + controller, stepped together at the model timestep."""

    def __init__(
        self,
        model: mujoco.MjModel,
        controller: Controller,
        limits: FallLimits | None = None,
    ) -> None:
        self.sim = Simulator(model, limits)
        self.model = model
        self.data = self.sim.data
        self.controller = controller
        self.limits = self.sim.limits
        self._feet = (model.site("left_foot").id, model.site("right_foot").id)

    @property
    def time(self) -> float:
        return self.sim.time

    def reset(self, qpos: Sequence[float], qvel: Sequence[float]) -> None:
        """Set the state (``JOINT_NAMES`` order) at t = 0 and zero the controls."""
        self.sim.reset(qpos, qvel)

    def push(self, force_x: float, duration: float, force_z: float = 0.0) -> None:
        """Apply a force (N, world frame) at the torso CoM for ``duration`` s from now."""
        self.sim.push(force_x, duration, force_z)

    def step(self) -> list[float]:
        """One control tick + one physics step; returns the commanded torques (N m)."""
        data = self.data
        torques = self.controller.compute(data.qpos.tolist(), data.qvel.tolist())
        self.sim.step(torques)
        return torques

    def run(
        self,
        duration: float,
        stop_on_fall: bool = True,
        on_tick: Callable[["ClosedLoop", list[float]], None] | None = None,
    ) -> WalkResult:
        """Run for ``duration`` s of sim time (from the current time) and summarise."""
        data, model = self.data, self.model
        n = int(round(duration / model.opt.timestep))
        start_time = data.time
        x_start = float(data.qpos[0])
        half_time = start_time + 0.5 * duration
        x_half: float | None = None
        touchdowns: list[Touchdown] = []
        peak = 0.0
        fell = False
        fall_time = None
        limits = self.limits
        controller = self.controller
        qpos = data.qpos
        for _ in range(n):
            torques = self.step()
            for tq in torques:
                if tq > peak:
                    peak = tq
                elif -tq > peak:
                    peak = -tq
            if controller.touchdown:
                stance = getattr(controller, "stance", 0)
                foot = data.site_xpos[self._feet[int(stance)]]
                touchdowns.append(Touchdown(float(data.time), float(foot[0]), float(qpos[0])))
            if x_half is None and data.time >= half_time:
                x_half = float(qpos[0])
            if on_tick is not None:
                on_tick(self, torques)
            if limits.fallen(qpos[1], qpos[2]):
                fell = True
                fall_time = float(data.time)
                if stop_on_fall:
                    break
        end_time = float(data.time)
        return summarise(
            touchdowns, fell, fall_time, start_time, end_time,
            x_half if x_half is not None else x_start, float(qpos[0]), peak,
        )


def summarise(
    touchdowns: list[Touchdown],
    fell: bool,
    fall_time: float | None,
    start_time: float,
    end_time: float,
    x_half: float,
    x_end: float,
    peak: float,
) -> WalkResult:
    """Mean forward speed, step length and step period over the second half of a walk
    (``x_half`` is the hip x at its midpoint, ``x_end`` at its end)."""
    half_time = 0.5 * (start_time + end_time)
    late = [td for td in touchdowns if td.time >= half_time]
    if len(late) >= 2:
        step_length = float(np.mean(np.diff([td.foot_x for td in late])))
        step_period = float(np.mean(np.diff([td.time for td in late])))
    else:
        step_length = step_period = float("nan")
    span = end_time - half_time
    return WalkResult(
        fell=fell,
        fall_time=fall_time,
        duration=end_time - start_time,
        steps=len(touchdowns),
        mean_speed=(x_end - x_half) / span if span > 0 else float("nan"),
        step_length=step_length,
        step_period=step_period,
        peak_torque=peak,
        touchdowns=touchdowns,
    )
