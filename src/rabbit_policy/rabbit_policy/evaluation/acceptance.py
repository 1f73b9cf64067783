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

import numpy as np

from rabbit_policy.runtime.policies import Policy
from rabbit_policy.experiment.walk import PolicyWalk, walk_policy

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
                         model_variant: str = "paper") -> dict:
    """Walk at one commanded speed; mean over the last ``average_over`` s."""
    walk = walk_policy(policy, ((0.0, speed),), criteria.constant_duration, model_variant=model_variant)
    mean = walk.mean_speed(criteria.constant_duration - criteria.average_over)
    error = mean - speed
    return {
        "speed": speed,
        "fell": walk.fell,
        "fall_time": walk.fall_time,
        "stalled": walk.stalled,
        "mean_speed_last": None if walk.failed else mean,
        "error": None if walk.failed else error,
        "rejected": walk.rejected,
        "passed": (not walk.failed) and abs(error) <= criteria.speed_tolerance,
    }


def reach_times(walk: PolicyWalk, schedule: tuple[tuple[float, float], ...], tolerance: float) -> list[float | None]:
    """For each schedule segment, seconds from its start to the first step (starting after
    the change) whose mean speed is within ``tolerance`` of the segment's speed; None if
    never within the segment."""
    bounds = [t for t, _ in schedule[1:]] + [float("inf")]
    previous_end = [0.0] + [s.time for s in walk.steps]
    result: list[float | None] = []
    for (start, speed), end in zip(schedule, bounds):
        reached = None
        for step, step_start in zip(walk.steps, previous_end):
            if step_start >= start - 1e-9 and step.time <= end and abs(step.mean_speed - speed) <= tolerance:
                reached = step.time - start
                break
        result.append(reached)
    return result


def segment_summaries(walk: PolicyWalk, schedule: tuple[tuple[float, float], ...], duration: float,
                      tolerance: float) -> list[dict]:
    """Per schedule segment (starting before ``duration``): start (s), speed (m/s), time to
    reach it (s, None if never, see :func:`reach_times`) and the mean hip speed over the
    segment's second half (m/s, None if the walk ended before)."""
    bounds = [t for t, _ in schedule[1:]] + [duration]
    segments = []
    for (start, speed), end, reach in zip(schedule, bounds, reach_times(walk, schedule, tolerance)):
        if start >= duration:
            break
        mean = walk.mean_speed(0.5 * (start + end), end)
        segments.append({"start": start, "speed": speed, "reach_time": reach,
                         "mean_speed_second_half": None if np.isnan(mean) else mean})
    return segments


def schedule_check(policy: Policy, schedule: tuple[tuple[float, float], ...] = ACCEPTANCE_SCHEDULE,
                   criteria: Criteria = Criteria(), model_variant: str = "paper") -> dict:
    """Walk the speed schedule; per segment: time to reach, mean over its second half."""
    duration = schedule[-1][0] + criteria.segment_duration
    walk = walk_policy(policy, schedule, duration, model_variant=model_variant)
    segments = segment_summaries(walk, schedule, duration, criteria.speed_tolerance)
    for segment in segments:
        reach = segment["reach_time"]
        segment["passed"] = reach is not None and reach <= criteria.reach_within
    return {
        "schedule": [list(s) for s in schedule],
        "fell": walk.fell,
        "fall_time": walk.fall_time,
        "stalled": walk.stalled,
        "segments": segments,
        "passed": (not walk.failed) and all(s["passed"] for s in segments),
    }


def _check(job: tuple) -> dict:
    """One acceptance walk (a module-level function so a process pool can run it)."""
    kind, policy, value, criteria, model_variant = job
    if kind == "constant":
        return constant_speed_check(policy, value, criteria, model_variant)
    return schedule_check(policy, value, criteria, model_variant)


def acceptance(policy: Policy, criteria: Criteria = Criteria(), model_variant: str = "paper",
               speeds: tuple[float, ...] = ACCEPTANCE_SPEEDS,
               map_fn: Callable[[Callable, Iterable], Iterable] = map) -> dict:
    """All checks: ``{"constant": [...], "schedule": {...}, "passed", "failures",
    "total_error"}``. ``map_fn`` runs the independent walks (e.g. a process pool's
    ``map``; the policy must then pickle)."""
    jobs = [("constant", policy, v, criteria, model_variant) for v in speeds]
    jobs.append(("schedule", policy, ACCEPTANCE_SCHEDULE, criteria, model_variant))
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
