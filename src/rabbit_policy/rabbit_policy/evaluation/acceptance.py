"""The HZD-RL acceptance checks (the learning issue), on the ROS-free fast path.

* Constant speed: for every V in 0.7, 0.8, ..., 1.5 m/s, 30 s without a fall and the
  mean hip speed over the last 15 s within 0.05 m/s of V.
* Speed changes: the schedule 0.8 -> 1.2 -> 0.9 -> 1.5 -> 0.7 m/s, 10 s each, without a
  fall; each new speed reached within 4 s. "Reached" = the first step that starts after
  the change whose mean hip speed (touchdown to touchdown, the one-step average) is
  within 0.05 m/s of the new speed; the time is that step's touchdown minus the change.

Every check returns plain dicts (JSON-ready) with the measured figures and a ``passed``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable


from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import Policy
from rabbit_sim.model import ModelOptions

ACCEPTANCE_SPEEDS = tuple(round(0.7 + 0.1 * i, 1) for i in range(9))
ACCEPTANCE_SCHEDULE = ((0.0, 0.8), (10.0, 1.2), (20.0, 0.9), (30.0, 1.5), (40.0, 0.7))


@dataclass(frozen=True)
class Criteria:
    """Tolerances (m/s) and durations (s) of the acceptance checks."""

    constant_duration: float = 30.0
    average_over: float = 15.0
    speed_tolerance: float = 0.05
    segment_duration: float = 10.0
    reach_within: float = 4.0


def constant_speed_check(policy: Policy, speed: float, criteria: Criteria = Criteria(),
                         model: ModelOptions = ModelOptions()) -> dict:
    """Walk at one commanded speed; mean over the last ``average_over`` s."""
    result = walk(policy, Scenario.constant(speed, model=model), criteria.constant_duration)
    mean = result.mean_speed(criteria.constant_duration - criteria.average_over)
    error = mean - speed
    return {
        "speed": speed,
        "fell": result.fell,
        "fall_time": result.fall_time,
        "stalled": result.stalled,
        "mean_speed_last": None if result.failed else mean,
        "error": None if result.failed else error,
        "rejected": result.rejected,
        "passed": (not result.failed) and abs(error) <= criteria.speed_tolerance,
    }


def schedule_check(policy: Policy, schedule: tuple[tuple[float, float], ...] = ACCEPTANCE_SCHEDULE,
                   criteria: Criteria = Criteria(), model: ModelOptions = ModelOptions()) -> dict:
    """Walk the speed schedule; per segment: time to reach, mean over its second half."""
    duration = schedule[-1][0] + criteria.segment_duration
    result = walk(policy, Scenario(schedule=schedule, model=model), duration)
    segments = result.segments(criteria.speed_tolerance)
    for segment in segments:
        reach = segment["reach_time"]
        segment["passed"] = reach is not None and reach <= criteria.reach_within
    return {
        "schedule": [list(s) for s in schedule],
        "fell": result.fell,
        "fall_time": result.fall_time,
        "stalled": result.stalled,
        "segments": segments,
        "passed": (not result.failed) and all(s["passed"] for s in segments),
    }


def _check(job: tuple) -> dict:
    """One acceptance walk (a module-level function so a process pool can run it)."""
    kind, policy, value, criteria, model = job
    if kind == "constant":
        return constant_speed_check(policy, value, criteria, model)
    return schedule_check(policy, value, criteria, model)


def acceptance(policy: Policy, criteria: Criteria = Criteria(), model: ModelOptions = ModelOptions(),
               speeds: tuple[float, ...] = ACCEPTANCE_SPEEDS,
               map_fn: Callable[[Callable, Iterable], Iterable] = map) -> dict:
    """All checks: ``{"constant": [...], "schedule": {...}, "passed", "failures",
    "total_error"}``. ``map_fn`` runs the independent walks (e.g. a process pool's
    ``map``; the policy must then pickle)."""
    jobs = [("constant", policy, v, criteria, model) for v in speeds]
    jobs.append(("schedule", policy, ACCEPTANCE_SCHEDULE, criteria, model))
    *constant, schedule = list(map_fn(_check, jobs))
    checks = [c["passed"] for c in constant] + [s["passed"] for s in schedule["segments"]]
    failures = sum(not ok for ok in checks) + int(schedule["fell"])
    total_error = sum(abs(c["error"]) if c["error"] is not None else 1.0 for c in constant) + sum(
        s["reach_time"] / criteria.segment_duration if s["reach_time"] is not None else 1.0
        for s in schedule["segments"])
    return {"policy": policy.name, "constant": constant, "schedule": schedule,
            "passed": failures == 0, "failures": failures, "total_error": total_error}


def acceptance_rank(result: dict) -> tuple[int, float]:
    """Sort key, lower is better: failed checks, then the summed errors (constant-speed
    |error| in m/s + reach times as a fraction of the segment)."""
    return result["failures"], result["total_error"]
