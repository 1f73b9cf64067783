"""Walk RABBIT with a gait policy in the loop, without ROS: the fast path of the node stack.

Each tick the closed loop (same MuJoCo model, same :class:`HZDController` as the nodes)
steps once and the hip speed goes into a :class:`~.speed_window.SpeedWindow`. At each
touchdown the policy sees the window's observation and its gait is queued for the next
touchdown, exactly as ``policy_node`` answers ``/hzd/step`` and as ``RabbitHZD-v0``
applies an action. The commanded speed follows a schedule of (start time s, speed m/s);
pushes are forces on the torso. The robot starts at phase 0 of the policy's first gait
(observation (v0, v0, 0)), moving at v0, as the node stack places it.

Used by ``scripts/walk.py``, the acceptance checks (:mod:`.acceptance`), training
(time to a passing policy) and the evaluation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from rabbit_sim.model import load_model

from rabbit_policy.runtime.policies import Policy
from rabbit_policy.experiment.scenario import Push, validate_schedule
from rabbit_policy.runtime.speed_window import Observation, SpeedWindow
from rabbit_policy.experiment.setup import loop_on_gait


@dataclass(frozen=True)
class StepRecord:
    """One completed step: touchdown time (s), mean hip speed over the step (m/s; the
    policy's observation: at most ``window`` ticks, a step is 390-730), the commanded
    speed at the touchdown (m/s) and the Kd the policy chose for the next step."""

    time: float
    mean_speed: float
    desired_speed: float
    kd: float


@dataclass
class PolicyWalk:
    """What happened: per-tick sim time (s) and hip speed (m/s, world x), per-step records,
    whether and when it fell, whether and when it stalled (no touchdown for
    ``stall_after`` s: standing still with the robot upright, e.g. stopped by a push),
    how many policy decisions the controller rejected; with
    ``record_state`` also the per-tick ``qpos``/``qvel`` (n x 7: hip x, z (m), torso
    pitch, left hip, left knee, right hip, right knee (rad); rates in m/s, rad/s) and the
    stance leg per tick (0 left, 1 right)."""

    fell: bool
    fall_time: float | None
    times: np.ndarray
    hip_speed: np.ndarray
    desired_speed: np.ndarray
    steps: list[StepRecord] = field(default_factory=list)
    rejected: int = 0
    qpos: np.ndarray | None = None
    qvel: np.ndarray | None = None
    stance: np.ndarray | None = None
    stalled: bool = False
    stall_time: float | None = None

    @property
    def failed(self) -> bool:
        """Fell or stalled: the walk did not go on."""
        return self.fell or self.stalled

    @property
    def duration(self) -> float:
        return float(self.times[-1]) if len(self.times) else 0.0

    def mean_speed(self, start: float, end: float | None = None) -> float:
        """Time average of the hip speed over [start, end] s (NaN if no sample)."""
        end = self.duration if end is None else end
        mask = (self.times > start) & (self.times <= end + 1e-9)
        return float(self.hip_speed[mask].mean()) if mask.any() else float("nan")


def walk_policy(policy: Policy, schedule: Sequence[tuple[float, float]], duration: float,
                pushes: Sequence[Push] = (), model_variant: str = "paper", window: int = 1000,
                stop_on_fall: bool = True, record_state: bool = False, stall_after: float = 2.0) -> PolicyWalk:
    """Walk ``duration`` s of sim time with ``policy`` choosing every step's gait.

    ``schedule``: (start time s, commanded speed m/s), first at t = 0, times increasing.
    A fall, or a stall (no touchdown for ``stall_after`` s; a step takes 0.4-0.7 s),
    ends the walk unless ``stop_on_fall`` is False."""
    validate_schedule(schedule)
    if not duration > 0:
        raise ValueError("duration must be > 0")
    model = load_model(model_variant)
    speed = float(schedule[0][1])
    first = policy.act(Observation(speed, speed, 0.0))
    loop = loop_on_gait(model, first.alpha, first.kd, speed)
    controller, data, limits = loop.controller, loop.data, loop.limits
    speed_window = SpeedWindow(window)

    n = int(round(duration / model.opt.timestep))
    times, speeds, desired = np.empty(n), np.empty(n), np.empty(n)
    qpos = np.empty((n, model.nq)) if record_state else None
    qvel = np.empty((n, model.nv)) if record_state else None
    stance = np.empty(n, dtype=np.int8) if record_state else None
    changes = list(schedule[1:])
    pending_pushes = sorted(pushes, key=lambda p: p.time)
    steps: list[StepRecord] = []
    rejected = 0
    fell, fall_time = False, None
    stalled, stall_time = False, None
    last_touchdown_time = 0.0
    count = 0
    previous_touchdown: int | None = None
    for i in range(n):
        loop.step()
        t = float(data.time)
        while changes and t >= changes[0][0] - 1e-9:
            speed = float(changes.pop(0)[1])
        while pending_pushes and t >= pending_pushes[0].time - 1e-9:
            push = pending_pushes.pop(0)
            loop.push(push.force_x, push.duration)
        v = float(data.qvel[0])
        times[i], speeds[i], desired[i] = t, v, speed
        if record_state:
            qpos[i], qvel[i], stance[i] = data.qpos, data.qvel, int(controller.stance)
        count = i + 1
        speed_window.add(i, v, speed)
        if limits.fallen(data.qpos[1], data.qpos[2]):
            fell, fall_time = True, t
            if stop_on_fall:
                break
        if not stalled and t - last_touchdown_time > stall_after:
            stalled, stall_time = True, t
            if stop_on_fall:
                break
        if controller.touchdown:
            last_touchdown_time = t
            observation = speed_window.observation(speed, since_ns=previous_touchdown)  # this step's mean
            command = policy.act(observation)
            previous_touchdown = i
            try:
                controller.set_alpha(command.alpha)
                controller.queue_kd(command.kd)
            except ValueError:
                rejected += 1  # the controller keeps the gait in force, as the node does
            steps.append(StepRecord(t, observation.mean_speed, speed, command.kd))
    if record_state:
        qpos, qvel, stance = qpos[:count], qvel[:count], stance[:count]
    return PolicyWalk(fell, fall_time, times[:count], speeds[:count], desired[:count], steps, rejected,
                      qpos, qvel, stance, stalled, stall_time)
