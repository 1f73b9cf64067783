"""Push recovery on the ROS-free fast path: the paper's three scenarios, an impulse sweep and
repeated pushes.

The paper pushes the torso at t = 2, 4 and 6 s with "small forward", "small backward"
and "large backward" forces but gives no magnitudes; ours are in :data:`PUSH_SCENARIOS`
(a horizontal force at the torso's centre of mass, world frame, for ``duration`` s; the
impulse is force x duration in N s). They were set from the impulse sweep at 1.0 m/s
(``docs/results``): both controllers survive every push phase up to 9 N s backward and
17-22 N s forward, so "small" (±6 N s) is inside both margins and "large backward"
(15 N s) beyond both — in the paper the large push is one classic HZD does not survive. Every walk starts on the controller's gait at the
commanded speed, as :class:`~rabbit_policy.experiment.loop.ClosedLoop` places it.

The sweep goes beyond the paper: one push of growing impulse (fixed duration), applied
at several phases of a step, and the largest impulse each controller survives at every
phase (a walk survives when it neither falls nor stalls within ``horizon`` s after the
push; a stall is no touchdown for 2 s, the robot stopped upright).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np

from rabbit_policy.runtime.policies import Policy
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.result import WalkResult
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_sim.physics.model import ModelOptions


CLASSIC_MARGINS = {-1: ((0.7, 5.0), (1.0, 9.0), (1.3, 14.0)), 1: ((0.7, 25.0), (1.0, 16.0), (1.3, 11.0))}
"""Classic HZD's push margins (N s; direction -1 backward, +1 forward) at 0.7, 1.0 and 1.3 m/s,
check 4 of checks 1-6 (docs/learning.md; the largest 0.1 s push survived at all 8 phases of a
step): the scale of the training curriculum
(:attr:`~rabbit_policy.learning.env.EpisodeDistribution.relative_impulse`) and of the
validation pushes (:mod:`.acceptance`), linear between the speeds and held beyond them."""


def classic_margin(speed: float, direction: int) -> float:
    """Classic HZD's push margin (N s) at ``speed`` m/s pushing ``direction`` (+1 forward,
    -1 backward), interpolated in :data:`CLASSIC_MARGINS`."""
    speeds, margins = zip(*CLASSIC_MARGINS[direction])
    return float(np.interp(speed, speeds, margins))


@dataclass(frozen=True)
class PushScenario:
    """Pushes of ``force_x`` N (positive: forward) lasting ``duration`` s at ``times`` s."""

    name: str
    force_x: float
    duration: float = 0.1
    times: tuple[float, ...] = (2.0, 4.0, 6.0)

    @property
    def impulse(self) -> float:
        """N s per push (signed)."""
        return self.force_x * self.duration

    @property
    def pushes(self) -> tuple[Push, ...]:
        return tuple(Push(t, self.force_x, self.duration) for t in self.times)

    def to_dict(self) -> dict:
        return {"name": self.name, "force_x_N": self.force_x, "duration_s": self.duration,
                "impulse_Ns": self.impulse, "times_s": list(self.times)}


PUSH_SCENARIOS = (
    PushScenario("small_forward", 60.0),
    PushScenario("small_backward", -60.0),
    PushScenario("large_backward", -150.0),
)


def push_trial(policy: Policy, speed: float, scenario: PushScenario, duration: float = 10.0,
               model: ModelOptions = ModelOptions(), record_state: bool = False) -> WalkResult:
    """Walk at ``speed`` m/s for ``duration`` s with the scenario's pushes (stops at a fall)."""
    return walk(policy, Scenario.constant(speed, pushes=scenario.pushes, model=model), duration,
                record_state=record_state)


def survives(policy: Policy, speed: float, impulse: float, push_time: float, duration: float = 0.1,
             horizon: float = 5.0, model: ModelOptions = ModelOptions()) -> bool:
    """One push of ``impulse`` N s (signed) over ``duration`` s at ``push_time`` s; True if
    the robot is still up and walking ``horizon`` s later (neither fell nor stalled)."""
    push = Push(push_time, impulse / duration, duration)
    return not walk(policy, Scenario.constant(speed, pushes=(push,), model=model), push_time + horizon).failed


@dataclass(frozen=True)
class SweepConfig:
    """Impulse grid (N s, magnitudes), push duration (s), push times (s: spread over about
    one step after a settling walk) and the survival horizon (s)."""

    impulses: tuple[float, ...] = tuple(round(1.0 * k, 1) for k in range(1, 31))
    duration: float = 0.1
    push_times: tuple[float, ...] = (3.0, 3.1, 3.2, 3.3, 3.4)
    horizon: float = 5.0


def _survives_job(job: tuple) -> bool:
    policy, speed, impulse, time, config, model = job
    return survives(policy, speed, impulse, time, config.duration, config.horizon, model)


def impulse_sweep(policy: Policy, speed: float, direction: int, config: SweepConfig = SweepConfig(),
                  model: ModelOptions = ModelOptions(),
                  map_fn: Callable[[Callable, Iterable], Iterable] = map) -> dict:
    """Survival over the impulse grid in one ``direction`` (+1 forward, -1 backward).

    Returns ``{"direction", "impulses", "survived_fraction"` (per impulse, over the push
    times), ``"largest_survived"`` (the largest grid impulse such that it and every
    smaller one are survived at every push time; 0 if the first already fails)}``."""
    if direction not in (1, -1):
        raise ValueError("direction must be +1 (forward) or -1 (backward)")
    jobs = [(policy, speed, direction * impulse, t, config, model)
            for impulse in config.impulses for t in config.push_times]
    outcomes = np.array(list(map_fn(_survives_job, jobs)), dtype=bool).reshape(
        len(config.impulses), len(config.push_times))
    fraction = outcomes.mean(axis=1)
    largest = 0.0
    for impulse, ok in zip(config.impulses, outcomes.all(axis=1)):
        if not ok:
            break
        largest = impulse
    return {"direction": "forward" if direction > 0 else "backward", "impulses": list(config.impulses),
            "survived_fraction": fraction.tolist(), "largest_survived_Ns": largest}


@dataclass(frozen=True)
class RepeatedConfig:
    """Repeated pushes (beyond the paper; the shape of its scenarios, broadly): ``count`` equal
    backward pushes ``spacing`` s apart (``duration`` s each), the first at each of
    ``first_times`` s, for every impulse (N s, magnitudes) of every speed (m/s) in
    ``impulses``; a trial survives when the walk neither falls nor stalls within ``horizon`` s
    of the start. Pushes 2 s apart land within the four steps the recovery rule remembers
    (:class:`~rabbit_policy.runtime.recovery.StepMemory`), at phases that vary with the
    walk. The default impulses run from about classic's backward margin to twice the
    recovery controller's at 0.7 m/s and about its margin at 1.0 and 1.3 m/s."""

    impulses: tuple[tuple[float, tuple[float, ...]], ...] = (
        (0.7, (8.0, 10.0, 12.0, 14.0)), (1.0, (13.0, 16.0, 19.0, 22.0)), (1.3, (18.0, 22.0, 26.0, 30.0)))
    first_times: tuple[float, ...] = (2.0, 2.1, 2.2, 2.3, 2.4, 2.5)
    count: int = 3
    spacing: float = 2.0
    duration: float = 0.1
    horizon: float = 10.0

    def __post_init__(self) -> None:
        if not (isinstance(self.count, int) and self.count >= 1):
            raise ValueError(f"RepeatedConfig.count must be a whole number >= 1, got {self.count!r}")
        if not (self.spacing > 0.0 and self.duration > 0.0 and self.first_times):
            raise ValueError("RepeatedConfig: spacing and duration > 0 s and at least one first push time")
        last = max(self.first_times) + (self.count - 1) * self.spacing + self.duration
        if not self.horizon > last:
            raise ValueError(f"RepeatedConfig.horizon ({self.horizon} s) must end after the last push ({last:g} s)")
        for speed, impulses in self.impulses:
            if not (speed > 0.0 and impulses and all(i > 0.0 for i in impulses)):
                raise ValueError(f"RepeatedConfig.impulses: a speed > 0 m/s with magnitudes > 0 N s, got "
                                 f"{speed!r}: {impulses!r}")

    def scenario(self, impulse: float, first: float) -> PushScenario:
        """The trial's pushes: ``count`` backward pushes of ``impulse`` N s from ``first`` s."""
        times = tuple(round(first + k * self.spacing, 9) for k in range(self.count))
        return PushScenario(f"repeated_{impulse:g}", -impulse / self.duration, self.duration, times)

    def to_dict(self) -> dict:
        return {"impulses_Ns": {f"{speed:.2f}": list(imps) for speed, imps in self.impulses},
                "first_times_s": list(self.first_times), "count": self.count, "spacing_s": self.spacing,
                "push_duration_s": self.duration, "horizon_s": self.horizon}


def _repeated_job(job: tuple) -> bool:
    policy, speed, scenario, horizon, model = job
    return not push_trial(policy, speed, scenario, horizon, model).failed


def repeated_pushes(policy: Policy, config: RepeatedConfig = RepeatedConfig(), model: ModelOptions = ModelOptions(),
                    map_fn: Callable[[Callable, Iterable], Iterable] = map) -> dict:
    """Trials survived per speed and impulse (over ``config.first_times``), and in all:
    ``{"by_speed": {"0.70": {"8": n, ...}, ...}, "survived": n, "trials": n}``."""
    cells = [(speed, impulse) for speed, impulses in config.impulses for impulse in impulses]
    jobs = [(policy, speed, config.scenario(impulse, first), config.horizon, model)
            for speed, impulse in cells for first in config.first_times]
    outcomes = np.array(list(map_fn(_repeated_job, jobs)), dtype=bool).reshape(len(cells), len(config.first_times))
    by_speed: dict[str, dict[str, int]] = {}
    for (speed, impulse), row in zip(cells, outcomes):
        by_speed.setdefault(f"{speed:.2f}", {})[f"{impulse:g}"] = int(row.sum())
    return {"by_speed": by_speed, "survived": int(outcomes.sum()), "trials": int(outcomes.size)}


def scenario_table(trials: dict[str, dict[str, WalkResult]], scenarios: Sequence[PushScenario]) -> list[dict]:
    """Rows ``{"scenario", controller: walk.outcome()}`` from walks keyed by controller,
    then scenario name."""
    rows = []
    for scenario in scenarios:
        row: dict = {"scenario": scenario.name}
        for controller, walks in trials.items():
            row[controller] = walks[scenario.name].outcome()
        rows.append(row)
    return rows


@dataclass(frozen=True)
class Neighbourhood:
    """The trials around one of the paper's push scenarios: its pushes shifted together by
    each of ``shifts`` s (a span longer than one step, so the pushes land at every phase) at
    each of ``speeds`` m/s; a trial walks when the walk neither falls nor stalls within
    ``duration`` s. The scenario at the nominal speed and shift 0 is one of the trials."""

    shifts: tuple[float, ...] = tuple(round(0.05 * k, 2) for k in range(-6, 7))
    speeds: tuple[float, ...] = (0.9, 0.95, 1.0, 1.05, 1.1)
    duration: float = 10.0

    def __post_init__(self) -> None:
        if not (self.shifts and self.speeds and all(s > 0.0 for s in self.speeds)):
            raise ValueError("Neighbourhood: at least one shift and one speed, speeds > 0 m/s")

    def trials(self, scenario: PushScenario) -> list[tuple[float, PushScenario]]:
        """(speed, the scenario with its pushes shifted) for every trial, speeds outermost."""
        shifted = [PushScenario(scenario.name, scenario.force_x, scenario.duration,
                                tuple(round(t + shift, 9) for t in scenario.times)) for shift in self.shifts]
        if any(min(s.times) <= 0.0 or max(s.times) + s.duration >= self.duration for s in shifted):
            raise ValueError(f"Neighbourhood: {scenario.name}'s shifted pushes must fall inside (0, {self.duration}) s")
        return [(speed, s) for speed in self.speeds for s in shifted]

    def to_dict(self) -> dict:
        return {"shifts_s": list(self.shifts), "speeds_mps": list(self.speeds), "duration_s": self.duration}


def _walked_job(job: tuple) -> bool:
    policy, speed, scenario, duration, model = job
    return not push_trial(policy, speed, scenario, duration, model).failed


def neighbourhood_outcomes(policy: Policy, scenario: PushScenario, config: Neighbourhood = Neighbourhood(),
                           model: ModelOptions = ModelOptions(),
                           map_fn: Callable[[Callable, Iterable], Iterable] = map) -> list[bool]:
    """Whether each trial of ``config.trials(scenario)`` walked, in that order."""
    jobs = [(policy, speed, shifted, config.duration, model) for speed, shifted in config.trials(scenario)]
    return [bool(walked) for walked in map_fn(_walked_job, jobs)]
