"""The broad evaluation an outside researcher runs: every speed, every ordered speed change at
several phases of a step, random command sequences, the push margin at every phase of a step,
and model errors — for any policy, on the one closed loop (:mod:`rabbit_policy.experiment`).

Definitions (times s, speeds m/s, impulses N s):

* **speed grid**: a constant command for ``grid_duration``; the error is the last-half mean
  speed minus the command; a point passes when the walk neither fell nor stalled and
  |error| <= ``grid_tolerance``.
* **transition** a -> b at phase phi: walk at a; the change comes at phase phi of the first
  step that starts after ``transition_settle`` (phase = fraction of that step's duration,
  from the unperturbed walk at a, which is identical up to the change); passes when it
  neither falls nor stalls within ``transition_horizon`` after the change and b is
  reached (the first whole step after the change within 0.05 of b) within ``reach_within``.
* **random sequence**: a new command uniform in the speed range every 2-5 s (uniform) for
  ``random_duration``; passes when it neither falls nor stalls. Seeded per episode.
* **push margin** at a speed and direction: the largest impulse (a ``push_duration`` push on
  the torso, whole N s steps) such that it and every smaller one are survived (no fall, no
  stall within ``push_horizon``) at every one of ``push_phases`` phases of the first step
  after ``push_settle``.
* **survival against impulse** in a direction: one push of each ``curve_impulses`` impulse at
  each of ``push_phases`` phases of the first step after ``push_settle`` at each of
  ``curve_speeds``; the survival rate per impulse over those trials with its 95 % Wilson
  interval, and the impulse survived in 90 % of them (:func:`impulse_at`), a margin defined
  on the curve rather than on its weakest point.
* **model errors**: the walk at each ``model_speeds`` command under each
  :data:`MODEL_ERRORS` case; passes when it neither falls nor stalls and |error| <= 0.05.

Every function takes ``map_fn`` (a process pool's ``map`` runs the walks in parallel) and
returns JSON-ready dicts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable

import numpy as np

from rabbit_policy.evaluation.statistics import rate
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.result import REACH_TOLERANCE, REACH_WITHIN
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.runtime.policies import Policy
from rabbit_sim.physics.model import ModelOptions

MapFn = Callable[[Callable, Iterable], Iterable]


@dataclass(frozen=True)
class ModelError:
    """One model-error case: a name, the model options and a torque delay (s)."""

    name: str
    model: ModelOptions = field(default_factory=ModelOptions)
    torque_delay: float = 0.0


MODEL_ERRORS = (
    ModelError("paper"),
    ModelError("drives", ModelOptions("drives")),
    ModelError("friction 0.5", ModelOptions(friction=0.5)),
    ModelError("friction 0.4", ModelOptions(friction=0.4)),
    ModelError("friction 0.3", ModelOptions(friction=0.3)),
    ModelError("torso mass -15 %", ModelOptions(torso_mass_scale=0.85)),
    ModelError("torso mass +15 %", ModelOptions(torso_mass_scale=1.15)),
    ModelError("torso mass +25 %", ModelOptions(torso_mass_scale=1.25)),
    ModelError("torque delay 3 ms", torque_delay=0.003),
    ModelError("torque delay 5 ms", torque_delay=0.005),
)


def _grid(lo: float, hi: float, step: float) -> tuple[float, ...]:
    return tuple(round(lo + step * i, 2) for i in range(int(round((hi - lo) / step)) + 1))


@dataclass(frozen=True)
class RobustnessConfig:
    """What :func:`robustness` runs (see the module docstring for the definitions)."""

    grid_speeds: tuple[float, ...] = _grid(0.7, 1.5, 0.01)
    grid_duration: float = 30.0
    grid_tolerance: float = 0.03
    transition_speeds: tuple[float, ...] = _grid(0.7, 1.5, 0.1)
    change_phases: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75)
    transition_settle: float = 6.0
    transition_horizon: float = 6.0
    reach_within: float = REACH_WITHIN
    random_episodes: int = 100
    random_duration: float = 60.0
    random_interval: tuple[float, float] = (2.0, 5.0)
    speed_range: tuple[float, float] = (0.7, 1.5)
    push_speeds: tuple[float, ...] = (0.7, 1.0, 1.3)
    push_phases: tuple[float, ...] = tuple(i / 8 for i in range(8))
    push_duration: float = 0.1
    push_settle: float = 3.0
    push_horizon: float = 5.0
    max_impulse: int = 40
    curve_speeds: tuple[float, ...] = (0.7, 0.85, 1.0, 1.15, 1.3)
    curve_impulses: tuple[float, ...] = tuple(float(i) for i in range(3, 40, 3))
    model_speeds: tuple[float, ...] = (0.7, 1.0, 1.3)
    model_duration: float = 30.0
    model_errors: tuple[ModelError, ...] = MODEL_ERRORS
    seed: int = 0

    @classmethod
    def quick(cls) -> "RobustnessConfig":
        """A small version for the test suite and a first look (seconds)."""
        return cls(grid_speeds=(0.75, 1.25), grid_duration=8.0, transition_speeds=(0.8, 1.4),
                   change_phases=(0.0, 0.5), transition_settle=3.0, random_episodes=2, random_duration=10.0,
                   push_speeds=(1.0,), push_phases=(0.0, 0.5), max_impulse=4, push_settle=2.0,
                   curve_speeds=(1.0,), curve_impulses=(3.0, 30.0),
                   push_horizon=3.0, model_speeds=(1.0,),
                   model_duration=8.0, model_errors=(MODEL_ERRORS[1], MODEL_ERRORS[3], MODEL_ERRORS[9]))

    def to_dict(self) -> dict:
        return {**{k: v for k, v in self.__dict__.items() if k != "model_errors"},
                "model_errors": [{"name": m.name, "model": m.model.to_dict(), "torque_delay_s": m.torque_delay}
                                 for m in self.model_errors]}


# ------------------------------------------------------------------ helpers
def _outcome(result) -> str:
    return "fell" if result.fell else "stalled" if result.stalled else "walked"


def phase_times(policy: Policy, speed: float, after: float, phases: Iterable[float],
                model: ModelOptions = ModelOptions()) -> list[float] | None:
    """Sim times at the given phases (fractions of the step's duration) of the first whole
    step that starts at or after ``after`` s, walking at ``speed`` with no disturbance (the
    walk is identical up to any later change, so these times place one exactly); None if
    the policy does not walk that long at ``speed`` (it fell or stalled)."""
    result = walk(policy, Scenario.constant(speed, model=model), after + 3.0)
    for start, end, _ in result.step_speeds():
        if start >= after - 1e-9:
            return [start + phase * (end - start) for phase in phases]
    return None


# ------------------------------------------------------------------ speed grid
def _grid_job(job: tuple) -> dict:
    policy, speed, config = job
    result = walk(policy, Scenario.constant(speed), config.grid_duration)
    mean = result.mean_speed(0.5 * config.grid_duration)
    error = None if result.failed else float(mean - speed)
    return {"speed": speed, "outcome": _outcome(result), "error": error,
            "passed": error is not None and abs(error) <= config.grid_tolerance}


def speed_grid(policy: Policy, config: RobustnessConfig, map_fn: MapFn = map) -> dict:
    rows = list(map_fn(_grid_job, [(policy, v, config) for v in config.grid_speeds]))
    errors = [abs(r["error"]) for r in rows if r["error"] is not None]
    return {"rows": rows, "passed": sum(r["passed"] for r in rows), "total": len(rows),
            "failed_speeds": [r["speed"] for r in rows if not r["passed"]],
            "fell_or_stalled": [r["speed"] for r in rows if r["outcome"] != "walked"],
            "worst_error": max(errors) if errors else None}


# ------------------------------------------------------------------ transitions
def transition_outcome(policy: Policy, a: float, b: float, change: float, config: RobustnessConfig) -> dict:
    """A command change from ``a`` to ``b`` m/s at ``change`` s, walked ``config.transition_horizon``
    s on: passed when it neither falls nor stalls and the hip reaches ``b`` (within
    ``REACH_TOLERANCE``) within ``config.reach_within`` s of the change."""
    result = walk(policy, Scenario(schedule=((0.0, a), (change, b))), change + config.transition_horizon)
    reach = result.reach_time(change, result.end_time, b, REACH_TOLERANCE)
    ok = not result.failed and reach is not None and reach <= config.reach_within
    return {"from": a, "to": b, "change_time": change, "outcome": _outcome(result), "reach_time": reach, "passed": ok}


def _transition_job(job: tuple) -> dict:
    policy, a, b, change, phase, config = job
    row = transition_outcome(policy, a, b, change, config)
    return {"from": a, "to": b, "phase": phase, **row}


def transitions(policy: Policy, config: RobustnessConfig, map_fn: MapFn = map) -> dict:
    starts = {a: phase_times(policy, a, config.transition_settle, config.change_phases)
              for a in config.transition_speeds}
    jobs = [(policy, a, b, t, phase, config) for a in config.transition_speeds for b in config.transition_speeds
            if a != b and starts[a] is not None for t, phase in zip(starts[a], config.change_phases)]
    rows = list(map_fn(_transition_job, jobs))
    rows += [{"from": a, "to": b, "phase": phase, "change_time": None, "outcome": "start failed",
              "reach_time": None, "passed": False}  # the policy does not even walk at a
             for a in config.transition_speeds if starts[a] is None
             for b in config.transition_speeds if a != b for phase in config.change_phases]
    pairs = {}
    for row in rows:
        pair = pairs.setdefault((row["from"], row["to"]), {"from": row["from"], "to": row["to"], "passed": True,
                                                          "fell_or_stalled": False, "slowest_reach": 0.0})
        pair["passed"] &= row["passed"]
        pair["fell_or_stalled"] |= row["outcome"] != "walked"
        reach = row["reach_time"]
        pair["slowest_reach"] = None if reach is None or pair["slowest_reach"] is None else max(
            pair["slowest_reach"], reach)
    matrix = list(pairs.values())
    return {"rows": rows, "pairs": matrix, "passed": sum(p["passed"] for p in matrix), "total": len(matrix),
            "fell_or_stalled": sum(p["fell_or_stalled"] for p in matrix)}


# ------------------------------------------------------------------ random sequences
def random_schedule(seed: int, config: RobustnessConfig) -> tuple[tuple[float, float], ...]:
    """A seeded command sequence: uniform speeds, uniform 2-5 s apart."""
    rng = np.random.default_rng(seed)
    lo, hi = config.speed_range
    schedule, t = [], 0.0
    while t < config.random_duration:
        schedule.append((round(t, 3), round(float(rng.uniform(lo, hi)), 3)))
        t += float(rng.uniform(*config.random_interval))
    return tuple(schedule)


def _random_job(job: tuple) -> dict:
    policy, seed, config = job
    schedule = random_schedule(seed, config)
    result = walk(policy, Scenario(schedule=schedule), config.random_duration)
    return {"seed": seed, "outcome": _outcome(result),
            "end_time": result.fall_time if result.fell else result.stall_time, "commands": len(schedule)}


def random_sequences(policy: Policy, config: RobustnessConfig, map_fn: MapFn = map) -> dict:
    seeds = [config.seed * 100_003 + k for k in range(config.random_episodes)]
    rows = list(map_fn(_random_job, [(policy, s, config) for s in seeds]))
    return {"rows": rows, "passed": sum(r["outcome"] == "walked" for r in rows), "total": len(rows)}


# ------------------------------------------------------------------ push margins
def push_survived(job: tuple) -> bool:
    """``(policy, speed m/s, push time s, impulse N s signed, config)``: True if the walk at
    ``speed`` pushed once (``config.push_duration`` s) neither falls nor stalls within
    ``config.push_horizon`` s after the push (the margin's rule; the recovery tuning's too)."""
    policy, speed, time, impulse, config = job
    push = Push(time, impulse / config.push_duration, config.push_duration)
    return not walk(policy, Scenario.constant(speed, pushes=(push,)), time + config.push_horizon).failed


def push_margin(policy: Policy, speed: float, direction: int, config: RobustnessConfig,
                map_fn: MapFn = map) -> dict:
    """Largest whole impulse (N s) survived at every phase, pushing ``direction`` (+1 forward,
    -1 backward); the phases that failed first."""
    times = phase_times(policy, speed, config.push_settle, config.push_phases)
    largest, failed_phases = 0, []
    if times is None:  # it does not walk at this speed unpushed
        return {"speed": speed, "direction": "forward" if direction > 0 else "backward",
                "largest_survived_Ns": 0, "capped": False, "first_failing_phases": list(config.push_phases),
                "start_failed": True}
    for impulse in range(1, config.max_impulse + 1):
        ok = list(map_fn(push_survived, [(policy, speed, t, direction * impulse, config) for t in times]))
        if not all(ok):
            failed_phases = [p for p, good in zip(config.push_phases, ok) if not good]
            break
        largest = impulse
    return {"speed": speed, "direction": "forward" if direction > 0 else "backward",
            "largest_survived_Ns": largest, "capped": largest == config.max_impulse,
            "first_failing_phases": failed_phases}


def push_margins(policy: Policy, config: RobustnessConfig, map_fn: MapFn = map) -> list[dict]:
    return [push_margin(policy, v, d, config, map_fn) for v in config.push_speeds for d in (1, -1)]


def impulse_at(level: float, impulses: list[float], rates: list[dict]) -> dict:
    """The impulse survived at ``level`` (a rate, e.g. 0.9) on a survival curve: the largest
    grid impulse before the survival rate first falls below ``level`` (0 if the first does),
    with the range the 95 % intervals allow: ``low``, before the interval's lower bound first
    falls below ``level``; ``high``, before its upper bound first does (pointwise intervals)."""
    def before(values: list[float]) -> float:
        last = 0.0
        for impulse, value in zip(impulses, values):
            if value < level:
                break
            last = impulse
        return last

    return {"level": level, "impulse_Ns": before([r["rate"] for r in rates]),
            "low_Ns": before([r["ci95"][0] for r in rates]), "high_Ns": before([r["ci95"][1] for r in rates])}


def survival_curve(policy: Policy, direction: int, config: RobustnessConfig, map_fn: MapFn = map) -> dict:
    """Survival against impulse pushing ``direction`` (+1 forward, -1 backward): every trial's
    outcome per impulse (speeds outermost, then phases; a speed the policy does not walk
    unpushed counts as failed), the rate per impulse and :func:`impulse_at` 90 %."""
    times = {v: phase_times(policy, v, config.push_settle, config.push_phases) for v in config.curve_speeds}
    trials = [(v, t) for v in config.curve_speeds for t in (times[v] or [None] * len(config.push_phases))]
    jobs = [(policy, v, t, direction * impulse, config) for impulse in config.curve_impulses for v, t in trials
            if t is not None]
    walked = iter(map_fn(push_survived, jobs))
    outcomes = [[t is not None and bool(next(walked)) for v, t in trials] for _impulse in config.curve_impulses]
    rates = [rate(row) for row in outcomes]
    return {"direction": "forward" if direction > 0 else "backward", "impulses_Ns": list(config.curve_impulses),
            "speeds": list(config.curve_speeds), "phases": list(config.push_phases), "outcomes": outcomes,
            "rates": rates, "at_90": impulse_at(0.9, list(config.curve_impulses), rates)}


# ------------------------------------------------------------------ model errors
def _model_job(job: tuple) -> dict:
    policy, case, speed, config = job
    scenario = Scenario.constant(speed, model=case.model, torque_delay=case.torque_delay)
    result = walk(policy, scenario, config.model_duration)
    error = None if result.failed else float(result.mean_speed(0.5 * config.model_duration) - speed)
    return {"case": case.name, "speed": speed, "outcome": _outcome(result), "error": error,
            "passed": error is not None and abs(error) <= 0.05}


def model_errors(policy: Policy, config: RobustnessConfig, map_fn: MapFn = map) -> dict:
    jobs = [(policy, case, v, config) for case in config.model_errors for v in config.model_speeds]
    rows = list(map_fn(_model_job, jobs))
    return {"rows": rows, "passed": sum(r["passed"] for r in rows), "total": len(rows)}


# ------------------------------------------------------------------ all
def robustness(policy: Policy, config: RobustnessConfig = RobustnessConfig(), map_fn: MapFn = map,
               log: Callable[[str], None] = lambda _message: None) -> dict:
    """Every part above for one policy."""
    log(f"{policy.name}: speed grid ({len(config.grid_speeds)} speeds)")
    grid = speed_grid(policy, config, map_fn)
    log(f"{policy.name}: transitions")
    changes = transitions(policy, config, map_fn)
    log(f"{policy.name}: random sequences")
    sequences = random_sequences(policy, config, map_fn)
    log(f"{policy.name}: push margins")
    pushes = push_margins(policy, config, map_fn)
    log(f"{policy.name}: survival against impulse")
    curves = [survival_curve(policy, d, config, map_fn) for d in (-1, 1)]
    log(f"{policy.name}: model errors")
    models = model_errors(policy, config, map_fn)
    return {"policy": policy.name, "speed_grid": grid, "transitions": changes, "random_sequences": sequences,
            "push_margins": pushes, "survival": curves, "model_errors": models}

