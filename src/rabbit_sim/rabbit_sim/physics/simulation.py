"""The RABBIT model stepped with given joint torques: the physics every experiment and
``sim_node`` run, with pushes on the torso, and the rules that end a walk.

No controller inside: ``sim_node`` steps a :class:`Simulator` with the torques that
arrive on ``/joint_torques``; the ROS-free closed loop (``rabbit_policy.experiment.loop``)
steps the very same class with the HZD controller's torques, so a ROS run and a ROS-free
run of the same controller produce the same numbers. One physics step (1 ms) = one
control tick.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import mujoco
import numpy as np

from rabbit_msgs_py.pushes import Push

from . import compiled


@dataclass(frozen=True)
class FallLimits:
    """The paper's episode limits: |torso pitch| < 0.5 rad and 0.6 m < hip height < 0.8 m.

    ``max_hip_height`` gets a small tolerance above the paper's 0.8 m because a straight
    vertical leg puts the hip at exactly 0.8 m (less the ~0.1 mm contact penetration)."""

    max_abs_pitch: float = 0.5
    min_hip_height: float = 0.6
    max_hip_height: float = 0.8 + 1e-3

    def fallen(self, hip_height: float, pitch: float) -> bool:
        """The compiled rule (:func:`.compiled.fallen`), hip height in m, pitch in rad."""
        return compiled.fallen(hip_height, pitch, self.min_hip_height, self.max_hip_height, self.max_abs_pitch)


@dataclass(frozen=True)
class StopRules:
    """What ends a walk, defined once for the fast path, training, the evaluation and the
    ROS stack's supervisor: a fall (:class:`FallLimits`), or a stall — no touchdown for
    ``stall_after`` s of sim time (a step takes 0.4-0.7 s; a robot stopped upright by a
    push stalls). ``roll_back_after`` > 0 (s; off by default, the training env's early
    failure rule): a stall is declared as soon as the hip has been behind its stance foot and
    moving backward for that long, the robot rolling back over its heel, which no walk that
    recovered ever did (docs/learning.md); the closed loop applies it, the ROS stack's
    supervisor does not (it refuses it)."""

    fall: FallLimits = field(default_factory=FallLimits)
    stall_after: float = 2.0
    roll_back_after: float = 0.0

    def __post_init__(self) -> None:
        if not self.stall_after > 0.0:
            raise ValueError(f"stall_after must be > 0 s, got {self.stall_after}")
        if not (math.isfinite(self.roll_back_after) and self.roll_back_after >= 0.0):
            raise ValueError(f"roll_back_after must be a finite number >= 0 s, got {self.roll_back_after}")

    def stalled(self, time: float, last_touchdown: float) -> bool:
        """True when no touchdown came for more than ``stall_after`` s (times in s)."""
        return time - last_touchdown > self.stall_after

    def stall_time(self, last_touchdown: float, tick: float = 0.001) -> float:
        """The sim time (s, on the ns grid) of the first tick at which :meth:`stalled` holds
        after a touchdown at ``last_touchdown``: where a walk that saw every state declares
        the stall (the stack's supervisor, which may miss states, dates it so too)."""
        n = math.floor((last_touchdown + self.stall_after) / tick)
        while not self.stalled(round(n * tick, 9), last_touchdown):
            n += 1
        return round(n * tick, 9)


class TorqueDelay:
    """Torques applied ``ticks`` ticks after they were computed, until then the first ones
    held: the one rule of a torque delay (:func:`.compiled.delay_torques`), run by the ROS-free
    loop and by ``sim_node`` (``torque_delay``), so the two walk the same."""

    def __init__(self, ticks: int) -> None:
        if not (isinstance(ticks, int) and ticks >= 1):
            raise ValueError(f"a torque delay is a whole number of ticks >= 1, got {ticks!r}")
        self.ticks = ticks
        self.queue = np.zeros((ticks, 4))
        self.count = np.zeros(1)
        self._torques = np.zeros(4)
        self._out = np.zeros(4)

    def clear(self) -> None:
        """Forget the torques in flight (the robot was placed again)."""
        self.count[0] = 0.0

    def __call__(self, torques: Sequence[float]) -> list[float]:
        """The torques to apply this tick, given the ones computed for it (N m)."""
        self._torques[:] = torques
        compiled.delay_torques(self.queue, self.count, self._torques, self._out)
        return self._out.tolist()


def timestep_ns(timestep: float) -> int:
    """A model timestep (s) as the whole ns of one tick; ``ValueError`` unless it is one
    (sim time is counted in ticks of whole ns)."""
    ns = round(timestep * 1e9)
    if not (ns >= 1 and abs(timestep * 1e9 - ns) < 1e-3):
        raise ValueError(f"the model's timestep must be a whole number of ns, got {timestep!r} s")
    return ns


class Simulator:
    """The RABBIT model stepped with given joint torques (no controller inside).

    One :meth:`step` applies four torques (N m, ``ACTUATED_JOINTS`` order, clipped by the
    actuators to +-150 N m) and advances one model timestep (1 ms). External pushes are a
    wrench on the torso (world frame) held for a duration: started now (:meth:`push`) or
    scheduled at sim times (:meth:`schedule_pushes`; a push due at t acts from the first
    step that starts at or after t, for ``round(duration / timestep)`` steps).
    ``push_changed`` is true after a step in which a push started or ended.

    Sim time is counted in whole steps: :attr:`tick` (steps since the last :meth:`reset`),
    :attr:`stamp` (``tick x tick_ns``, ns) and :attr:`time` (that stamp in s, the float
    nearest it). MuJoCo's ``data.time`` is its own float sum of timesteps and drifts off the
    ns grid after about 181,000 steps; nothing here reads it.
    """

    def __init__(self, model: mujoco.MjModel, limits: FallLimits | None = None) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        self.limits = limits or FallLimits()
        self._torso = model.body("torso").id
        self.bind()
        self._schedule: tuple[Push, ...] = ()
        self.push_state = np.zeros(compiled.PUSH_STATE_SIZE)  # compiled.push_rule's state
        self.push_state[compiled.PUSH_UNTIL] = -1.0
        self.push_schedule = np.zeros((0, 3))  # time s, force N, duration s, by time
        self._torques = np.zeros(4)
        self.tick_ns = timestep_ns(float(model.opt.timestep))
        self.tick = 0  # steps since the last reset

    def bind(self) -> None:
        """Keep views of the data's controls and the torso's row of ``xfrc_applied`` (MjData
        builds a new view on every access); again after the data was copied."""
        self._ctrl = self.data.ctrl
        self._wrench = self.data.xfrc_applied[self._torso]

    @property
    def wrench(self):
        """The torso's row of ``xfrc_applied`` (a live view: N, N m, world frame)."""
        return self._wrench

    @property
    def push_changed(self) -> bool:
        """True after a step in which a push started or ended."""
        return bool(self.push_state[compiled.PUSH_CHANGED])

    @property
    def pushes_started(self) -> int:
        """Pushes started so far (scheduled and :meth:`push`)."""
        return int(self.push_state[compiled.PUSHES_STARTED])

    @property
    def next_push_event(self) -> float:
        """Sim time (s) from which a step may end or start a push (inf: none pending); the
        compiled loop steps no further than the step before it without the rule's check."""
        state, schedule = self.push_state, self.push_schedule
        until = state[compiled.PUSH_UNTIL]
        end = until - 0.5 * self.model.opt.timestep if until >= 0.0 else math.inf
        i = int(state[compiled.NEXT_PUSH])
        start = schedule[i, 0] - compiled.PUSH_TIME_TOLERANCE if i < len(schedule) else math.inf
        return min(end, start)

    @property
    def stamp(self) -> int:
        """Simulation time (ns): the steps since the last reset times the timestep, exact."""
        return self.tick * self.tick_ns

    @property
    def time(self) -> float:
        """Simulation time (s): :attr:`stamp` as the float nearest it (on the ns grid)."""
        return self.stamp / 1e9

    @property
    def timestep(self) -> float:
        """Model timestep (s)."""
        return float(self.model.opt.timestep)

    def reset(self, qpos: Sequence[float], qvel: Sequence[float]) -> None:
        """Set the state (``JOINT_NAMES`` order) at t = 0 and zero controls and pushes
        (a push schedule stays: it applies again from t = 0)."""
        mujoco.mj_resetData(self.model, self.data)
        self.tick = 0
        self.data.qpos[:] = qpos
        self.data.qvel[:] = qvel
        self.push_state[compiled.PUSH_UNTIL] = -1.0
        self.push_state[compiled.PUSH_CHANGED] = 0.0
        mujoco.mj_forward(self.model, self.data)
        self._rearm()

    def schedule_pushes(self, pushes: Iterable[Push]) -> None:
        """Pushes to apply at their sim times (replaces any earlier schedule); those whose
        time has passed are dropped."""
        self._schedule = tuple(sorted(pushes, key=lambda p: p.time))
        self._rearm()

    def add_pushes(self, pushes: Iterable[Push]) -> None:
        """Add pushes to the schedule (those whose time has passed are dropped)."""
        self._schedule = tuple(sorted((*self._schedule, *pushes), key=lambda p: p.time))
        self._rearm()

    def _rearm(self) -> None:
        now = self.time
        self.push_schedule = np.array([(p.time, p.force_x, p.duration) for p in self._schedule], dtype=float
                                      ).reshape(-1, 3)
        due = [i for i, p in enumerate(self._schedule) if p.time >= now - compiled.PUSH_TIME_TOLERANCE]
        self.push_state[compiled.NEXT_PUSH] = due[0] if due else len(self._schedule)

    @property
    def push_wrench(self) -> tuple[float, float, float]:
        """The push acting now: (force x N, force z N, torque y N m), world frame; zeros
        when none."""
        wrench = self.data.xfrc_applied[self._torso]
        return float(wrench[0]), float(wrench[2]), float(wrench[4])

    def push(self, force_x: float, duration: float, force_z: float = 0.0, torque_y: float = 0.0) -> None:
        """Apply a wrench at the torso CoM, world frame (N, N, N m), for ``duration`` s
        from now (``round(duration / timestep)`` steps). Replaces a push still in progress."""
        wrench, state = self._wrench, self.push_state
        wrench[:] = 0.0
        wrench[0] = force_x
        wrench[2] = force_z
        wrench[4] = torque_y
        state[compiled.PUSH_UNTIL] = self.time + duration
        state[compiled.PUSH_CHANGED] = 1.0
        state[compiled.PUSHES_STARTED] += 1.0

    def step(self, torques: Sequence[float]) -> float:
        """Apply ``torques`` (N m, four) for one timestep and advance the physics; then end
        a push whose time is up and start scheduled pushes now due
        (:func:`.compiled.push_rule`). Returns the new sim time (s)."""
        data, ctrl = self.data, self._ctrl
        ctrl[0], ctrl[1], ctrl[2], ctrl[3] = torques
        mujoco.mj_step(self.model, data)
        self.tick += 1
        now = self.time
        compiled.push_rule(now, 0.5 * self.model.opt.timestep, self.push_state, self.push_schedule, self._wrench)
        return now

    def fallen(self) -> bool:
        """True when the paper's limits (torso pitch, hip height) are left."""
        qpos = self.data.qpos
        return self.limits.fallen(qpos[1], qpos[2])
