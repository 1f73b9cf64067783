"""What an experiment commands, ROS-free: a speed schedule, pushes on the torso, the model
(with its errors), a torque delay and the stop rules; and the text forms the scripts use
(``"0:0.8,10:1.2"``, ``"2:60:0.1,4:-80:0.2"``). The node stack (:mod:`..bringup`)
and the fast path (:mod:`.loop`) read the same schedules; pushes live in
:mod:`rabbit_msgs_py.pushes` because the simulator node parses them too."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

from rabbit_msgs_py.pushes import Push, format_pushes, parse_pushes
from rabbit_sim.physics.model import ModelOptions
from rabbit_sim.physics.simulation import StopRules

__all__ = ["PhasePush", "Push", "Scenario", "Schedule", "format_pushes", "parse_pushes", "parse_schedule", "validate_schedule"]

Schedule = tuple[tuple[float, float], ...]  # (start time s, commanded speed m/s)


MIN_SCHEDULE_SPACING = 0.1
"""s: the least time between two speed-schedule entries. A walking step lasts 0.4-0.7 s and
a policy decides every 20 ms; commands closer than this only flood the logs and the report
(8,000 entries 0.2 ms apart once gave 14,250 log lines)."""


def whole_ticks(seconds: float, tick: float = 0.001) -> int:
    """A duration (s) as the whole number of ticks (``tick`` s each) a walk of it runs."""
    return int(round(seconds / tick))


def first_tick_at(seconds: float, tick: float = 0.001) -> float:
    """The sim time (s) of the first tick at or after ``seconds``, on the ns grid: when a
    schedule change at ``seconds`` takes effect (6.0004 -> 6.001; 6.0 -> 6.0)."""
    return round(math.ceil(round(seconds / tick, 6)) * tick, 9)


def on_tick_grid(seconds: float, tick: float = 0.001) -> float:
    """The sim time (s) a walk of ``seconds`` ends at: its whole ticks, on the ns grid of
    the stack's stamps (16.132268 -> 16.132), so that a duration, a segment's end and the
    time the walk ended are the same number."""
    return round(whole_ticks(seconds, tick) * tick, 9)


def validate_schedule(schedule: Sequence[tuple[float, float]]) -> None:
    """Raise ``ValueError`` unless the schedule starts at t = 0, every entry is finite and
    its times increase by at least :data:`MIN_SCHEDULE_SPACING`."""
    if not schedule or schedule[0][0] != 0.0:
        raise ValueError("the speed schedule must start at t = 0")
    if not all(math.isfinite(t) and math.isfinite(v) for t, v in schedule):
        raise ValueError("speed schedule entries must be finite")
    times = [t for t, _ in schedule]
    if any(b <= a for a, b in zip(times, times[1:])):
        raise ValueError("speed schedule times must increase")
    close = next(((a, b) for a, b in zip(times, times[1:]) if b - a < MIN_SCHEDULE_SPACING - 1e-9), None)
    if close is not None:
        raise ValueError(f"speed schedule entries must be at least {MIN_SCHEDULE_SPACING} s apart, got "
                         f"{close[1] - close[0]:.4g} s between t = {close[0]:g} and {close[1]:g} s")


def parse_schedule(text: str) -> Schedule:
    """``"0:0.8,10:1.2"`` -> ((0.0, 0.8), (10.0, 1.2)); raises ``ValueError``."""
    pairs = []
    for item in text.split(","):
        try:
            t, v = (float(x) for x in item.split(":"))
        except ValueError:
            raise ValueError(f"speed schedule entries are time:speed, got {item!r}") from None
        if not (math.isfinite(t) and math.isfinite(v)) or t < 0:
            raise ValueError(f"bad speed schedule entry {item!r}")
        pairs.append((t, v))
    return tuple(pairs)


def format_schedule(schedule: Sequence[tuple[float, float]]) -> str:
    """The inverse of :func:`parse_schedule` (exact: floats in ``repr`` form)."""
    return ",".join(f"{t!r}:{v!r}" for t, v in schedule)


@dataclass(frozen=True)
class PhasePush:
    """A push placed by the walk's own steps (the fast path only: training and evaluations):
    at ``phase`` of the first step that starts at or after ``after`` s of sim time, force
    ``force_x`` N (world x, + forward) for ``duration`` s. The phase is a fraction of the
    step's duration, taken as the duration of the step before it (touchdown to touchdown), so
    a push lands at the same point of a step whatever the gait's step time: the common random
    numbers of a training population hold in phase, not only in time. The closed loop turns it
    into a :class:`Push` at that touchdown (``ClosedLoop.placed_pushes``)."""

    after: float
    phase: float
    force_x: float
    duration: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.after) and self.after >= 0.0):
            raise ValueError(f"PhasePush.after must be a finite time >= 0 s, got {self.after}")
        if not (math.isfinite(self.phase) and 0.0 <= self.phase < 1.0):
            raise ValueError(f"PhasePush.phase must be in [0, 1), got {self.phase}")
        if not math.isfinite(self.force_x):
            raise ValueError(f"PhasePush.force_x must be finite (N), got {self.force_x}")
        if not (math.isfinite(self.duration) and self.duration > 0.0):
            raise ValueError(f"PhasePush.duration must be finite and > 0 s, got {self.duration}")

    @property
    def impulse(self) -> float:
        """N s."""
        return self.force_x * self.duration

    def place(self, touchdown: float, step_duration: float) -> Push:
        """The push in time, for a step that starts at ``touchdown`` s and is taken to last
        ``step_duration`` s."""
        return Push(touchdown + self.phase * step_duration, self.force_x, self.duration)


@dataclass(frozen=True)
class Scenario:
    """One experiment's conditions (times s, speeds m/s).

    schedule: commanded speed from each start time on (first at t = 0); each time is taken
        as the first 1 ms tick at or after it (:func:`first_tick_at`), where the change takes
        effect, so that every time a walk reports is on the tick grid.
    pushes: pushes on the torso at sim times (:class:`~rabbit_msgs_py.pushes.Push`).
    phase_pushes: pushes at a phase of a step (:class:`PhasePush`; the fast path only).
    model: the model and its errors (:class:`~rabbit_sim.physics.model.ModelOptions`).
    torque_delay: the torques computed at a tick are applied this many seconds later
        (a multiple of the 1 ms timestep; until then the first torques are held).
    rules: fall and stall (:class:`~rabbit_sim.physics.simulation.StopRules`).
    window: longest speed window of the policy's observation (ticks), as ``policy_node``.
    """

    schedule: Schedule = ((0.0, 1.0),)
    pushes: tuple[Push, ...] = ()
    phase_pushes: tuple[PhasePush, ...] = ()
    model: ModelOptions = field(default_factory=ModelOptions)
    torque_delay: float = 0.0
    rules: StopRules = field(default_factory=StopRules)
    window: int = 1000

    def __post_init__(self) -> None:
        validate_schedule(self.schedule)
        object.__setattr__(self, "schedule", tuple((first_tick_at(float(t)), float(v)) for t, v in self.schedule))
        object.__setattr__(self, "pushes", tuple(sorted(self.pushes, key=lambda p: p.time)))
        object.__setattr__(self, "phase_pushes", tuple(sorted(self.phase_pushes, key=lambda p: p.after)))
        ticks = self.torque_delay * 1000.0 if math.isfinite(self.torque_delay) else -1.0
        if not (ticks >= 0.0 and abs(ticks - round(ticks)) < 1e-6):
            raise ValueError(f"torque_delay must be a whole number of ms >= 0 s (1 ms ticks), got {self.torque_delay}")
        if self.window < 1:
            raise ValueError(f"window must be >= 1 tick, got {self.window}")

    @classmethod
    def constant(cls, speed: float, **kwargs) -> "Scenario":
        """A scenario commanding ``speed`` m/s throughout."""
        return cls(schedule=((0.0, float(speed)),), **kwargs)

    @property
    def initial_speed(self) -> float:
        """The first commanded speed (m/s): the robot starts on the gait for it, moving at it."""
        return self.schedule[0][1]

    def to_dict(self) -> dict:
        """JSON-ready."""
        return {"schedule": [list(s) for s in self.schedule], "pushes": format_pushes(self.pushes),
                "phase_pushes": [{"after_s": p.after, "phase": p.phase, "force_N": p.force_x, "duration_s": p.duration}
                                 for p in self.phase_pushes],
                "model": self.model.to_dict(), "torque_delay_s": self.torque_delay,
                "stall_after_s": self.rules.stall_after}
