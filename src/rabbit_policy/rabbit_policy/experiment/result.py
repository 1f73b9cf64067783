"""What a walk returns: one result type for every experiment, with one definition of
mean speed.

**Mean speed** over (t0, t1] is the hip's forward displacement over the elapsed sim time,
``(x(t1) - x(t0)) / (t1 - t0)`` (m/s, world x), read from the per-tick samples. MuJoCo's
Euler step advances ``x`` by ``dt * v`` with the new velocity, so this equals the mean of
the per-tick hip speeds over the same ticks (to rounding): the policy's observation (the
mean over the last step) and a step's mean speed here are the same number.

* last-half mean speed: over the second half of the walk;
* a segment's mean speed: over the second half of the segment (the transient after the
  change is left out); None when the walk ended before the segment did;
* reach time of a segment: from its start to the touchdown ending the first whole step
  that began at or after the change and whose mean speed is within ``tolerance`` of the
  command (None: never within the segment).

Times are sim seconds on the ns grid of the stack's stamps (the ROS-free loop rounds
MuJoCo's float sum of 1 ms steps to it), and a walk of a duration runs its whole ticks and
is planned to end at that grid time (``scenario.on_tick_grid``): the fast path and the
stack report the same numbers, and a segment ends where the walk does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rabbit_msgs_py.decision_ticks import TICK_NS
from rabbit_msgs_py.strict_json import finite_or_none
from rabbit_policy.experiment.scenario import Scenario, first_tick_at, whole_ticks

TICK_S = TICK_NS / 1e9
"""The control tick (s)."""

REACH_TOLERANCE = 0.05
"""m/s: a speed is "reached" when a whole step's mean is this close to the command."""
REACH_WITHIN = 4.0
"""s: a commanded change passes the evaluation's reach rule when reached this soon after it."""
SETTLE_TOLERANCE = 0.03
"""m/s: a segment is "settled" when its mean speed (second half) is this close to its command."""


@dataclass(frozen=True)
class Touchdown:
    """One stance switch: sim time (s), new stance foot x (m), hip x (m), world frame. ``time``
    is the first state on the new stance, one tick after the state the controller switched on
    (what the loop's stall rule and a step's phases count from); :attr:`stamp` is that state's
    time, the one number a touchdown is reported by (``/hzd/step``'s stamp, walk.py's and
    run_stack's JSON)."""

    time: float
    foot_x: float
    hip_x: float

    @property
    def stamp(self) -> float:
        """Sim time (s) of the state on which the controller switched the stance: ``time`` less
        one tick, on the ms grid."""
        return round(self.time - TICK_S, 6)


@dataclass(frozen=True)
class Decision:
    """A policy decision at a touchdown: sim time (s), the observation's mean hip speed
    over the step just ended (m/s), the commanded speed then (m/s), the Kd chosen for the
    next step (N m s/rad) and whether the controller rejected the gait."""

    time: float
    mean_speed: float
    desired_speed: float
    kd: float
    rejected: bool = False


def mean_speed_between(t0: float, x0: float, t1: float, x1: float) -> float:
    """The one definition of mean speed: hip displacement over elapsed sim time (m/s) from
    (t0 s, x0 m) to (t1 s, x1 m); NaN for an empty span."""
    return (x1 - x0) / (t1 - t0) if t1 > t0 else float("nan")


def json_number(value: float | None) -> float | None:
    """``value`` for JSON: None for None, NaN or infinity (strict JSON has no NaN)."""
    return None if value is None else finite_or_none(float(value))


@dataclass
class WalkResult:
    """A walk on the closed loop (:mod:`.loop`). Times in s, positions in m, speeds in
    m/s, torques in N m.

    ``times``/``hip_x``: every tick's sim time and hip x after the step (the start state
    is ``start_time``/``start_x``). With ``record_state``: per-tick ``qpos``/``qvel``
    (n x 7, ``JOINT_NAMES`` order) and the stance leg (0 left, 1 right)."""

    scenario: Scenario
    fell: bool
    fall_time: float | None
    stalled: bool
    stall_time: float | None
    start_time: float
    start_x: float
    times: np.ndarray
    hip_x: np.ndarray
    touchdowns: list[Touchdown] = field(default_factory=list)
    decisions: list[Decision] = field(default_factory=list)
    peak_torque: float = 0.0
    qpos: np.ndarray | None = None
    qvel: np.ndarray | None = None
    stance: np.ndarray | None = None
    planned_duration: float | None = None  # s: how long the walk was to last (None: as long as it did)

    # ------------------------------------------------------------------ basics
    @property
    def failed(self) -> bool:
        """Fell or stalled: the walk did not go on."""
        return self.fell or self.stalled

    @property
    def end_time(self) -> float:
        return float(self.times[-1]) if len(self.times) else self.start_time

    @property
    def duration(self) -> float:
        """Simulated time (s)."""
        return self.end_time - self.start_time

    @property
    def steps(self) -> int:
        return len(self.touchdowns)

    @property
    def rejected(self) -> int:
        """Policy decisions the controller rejected (the gait in force stayed)."""
        return sum(d.rejected for d in self.decisions)

    @property
    def hip_speed(self) -> np.ndarray:
        """Per-tick hip speed (m/s): displacement over each tick."""
        x = np.concatenate(([self.start_x], self.hip_x))
        t = np.concatenate(([self.start_time], self.times))
        return np.diff(x) / np.diff(t)

    @property
    def desired_speed(self) -> np.ndarray:
        """Per-tick commanded speed (m/s)."""
        starts = np.array([t for t, _ in self.scenario.schedule])
        speeds = np.array([v for _, v in self.scenario.schedule])
        return speeds[np.searchsorted(starts, self.times + 1e-9, side="right") - 1]

    # -------------------------------------------------------------- mean speed
    def _sample(self, t: float) -> tuple[float, float]:
        """(time, hip x) of the last sample at or before ``t``."""
        i = int(np.searchsorted(self.times, t + 1e-9, side="right")) - 1
        return (self.start_time, self.start_x) if i < 0 else (float(self.times[i]), float(self.hip_x[i]))

    def mean_speed(self, start: float, end: float | None = None) -> float:
        """Mean speed over (start, end] (m/s, see the module docstring); NaN when no tick
        lies in between."""
        return mean_speed_between(*self._sample(start), *self._sample(self.end_time if end is None else end))

    def step_speeds(self) -> list[tuple[float, float, float]]:
        """Every whole step as (start s, end s, mean speed m/s), touchdown to touchdown
        (the first from the start of the walk)."""
        steps, t0, x0 = [], self.start_time, self.start_x
        for td in self.touchdowns:
            steps.append((t0, td.time, mean_speed_between(t0, x0, td.time, td.hip_x)))
            t0, x0 = td.time, td.hip_x
        return steps

    # ---------------------------------------------------------------- segments
    def segment_bounds(self) -> list[tuple[float, float, float]]:
        """(start s, end s, command m/s) of every schedule segment that began during the walk."""
        schedule = self.scenario.schedule
        planned = self.end_time if self.planned_duration is None else self.start_time + self.planned_duration
        ends = [t for t, _ in schedule[1:]] + [max(planned, schedule[-1][0])]
        return [(t, end, v) for (t, v), end in zip(schedule, ends) if t <= self.end_time + 1e-9]

    def reach_time(self, start: float, end: float, command: float, tolerance: float = REACH_TOLERANCE) -> float | None:
        """Seconds from the tick a change at ``start`` takes effect (the first at or after it) to
        the end of the first whole step starting at or after it (and ending by ``end``) whose
        mean speed is within ``tolerance`` of ``command``; whole ticks, so on the ms grid."""
        for step_start, step_end, speed in self.step_speeds():
            if step_start >= start - 1e-9 and step_end <= end + 1e-9 and abs(speed - command) <= tolerance:
                return (whole_ticks(step_end) - whole_ticks(first_tick_at(start))) / 1000.0
        return None

    def segments(self, tolerance: float = REACH_TOLERANCE) -> list[dict]:
        """Per schedule segment: ``command``, ``start``, ``end``, ``mean_speed`` (its second
        half; None if the walk ended first) and ``reach_time`` (None if never)."""
        rows = []
        for start, end, command in self.segment_bounds():
            complete = self.end_time >= end - 1e-9
            mean = self.mean_speed(0.5 * (start + end), end) if complete else float("nan")
            rows.append({"command": command, "start": start, "end": end, "mean_speed": json_number(mean),
                         "reach_time": self.reach_time(start, end, command, tolerance)})
        return rows

    def last_command_reached(self, tolerance: float = REACH_TOLERANCE) -> bool | None:
        """Did the walk reach its last commanded change (a whole step within ``tolerance`` of
        it, :meth:`reach_time`)? False for a walk that fell or stalled; None when there is no
        change to reach (one segment: the robot starts on the command's gait) or the last
        segment holds no whole step to judge."""
        segments = self.segments(tolerance)
        if self.failed:
            return False
        if len(segments) < 2:
            return None
        last = segments[-1]
        if last["reach_time"] is not None:
            return True
        whole = any(a >= last["start"] - 1e-9 and b <= last["end"] + 1e-9 for a, b, _ in self.step_speeds())
        return False if whole else None

    def tracking_scores(self, reach_within: float = REACH_WITHIN,
                        settle_tolerance: float = SETTLE_TOLERANCE) -> tuple[float, float]:
        """(reach, settle): the evaluation's two tracking rules as graded scores, summed over
        the walk's segments, every segment weighted alike whatever the size of its change.
        reach, per commanded change (each segment after the first): ``1 - t / reach_within``
        for a change reached (:meth:`reach_time`) after t <= ``reach_within`` s, else 0.
        settle, per segment: ``1 / (1 + (e / settle_tolerance)^2)`` with e (m/s) its mean
        speed's error (:meth:`segments`): 0.5 at the tolerance, near 0 far from it, 0 when
        the walk ended before the segment did. Both 0 for a walk that fell or stalled."""
        if self.failed:
            return 0.0, 0.0
        reach = settle = 0.0
        for k, segment in enumerate(self.segments()):
            t = segment["reach_time"]
            if k and t is not None and t <= reach_within:
                reach += 1.0 - t / reach_within
            if segment["mean_speed"] is not None:
                settle += 1.0 / (1.0 + ((segment["mean_speed"] - segment["command"]) / settle_tolerance) ** 2)
        return reach, settle

    def summary(self, tolerance: float = REACH_TOLERANCE) -> dict:
        """JSON-ready, always the same keys (no NaN: None instead)."""
        half = self.start_time + 0.5 * self.duration
        return {
            "fell": self.fell,
            "stalled": self.stalled,
            "fall_time": self.fall_time,
            "stall_time": self.stall_time,
            "duration": self.duration,
            "steps": self.steps,
            "mean_speed": None if self.failed else json_number(self.mean_speed(half)),
            "peak_torque": self.peak_torque,
            "rejected": self.rejected,
            "touchdowns": [td.stamp for td in self.touchdowns],  # as /hzd/step stamps them
            "segments": self.segments(tolerance),
            "last_command_reached": self.last_command_reached(tolerance),
        }

    def outcome(self) -> dict:
        """``{"outcome": "fell" | "stalled" | "walked", "fell", "fall_time", "stalled",
        "stall_time"}`` (times in s)."""
        result = "fell" if self.fell else "stalled" if self.stalled else "walked"
        return {"outcome": result, "fell": self.fell, "fall_time": self.fall_time, "stalled": self.stalled,
                "stall_time": self.stall_time}


def exit_status(summary: dict) -> int:
    """The exit status of ``walk.py`` and ``run_stack.py`` from a run's report
    (:func:`run_summary`): 1 fell or stalled, 3 not completed (interrupted, a node died, the
    policy stopped deciding), 4 walked to the end but never reached the last command (a last
    segment with whole steps, none within the tolerance), else 0."""
    if summary["fell"] or summary["stalled"]:
        return 1
    if not summary["completed"]:
        return 3
    return 4 if summary["last_command_reached"] is False else 0


def run_summary(controller: str, policy: str | None, result: WalkResult, wall_time: float,
                completed: bool = True, error: str | None = None,
                tolerance: float = REACH_TOLERANCE, decisions_lost: int | None = 0) -> dict:
    """The one JSON report of a walk, the same keys from ``walk.py --json`` (the fast path)
    and ``run_stack.py --json`` (the node stack): the controller and policy, the scenario,
    :meth:`WalkResult.summary`, the real-time factor (sim s per wall s; None if no time
    passed), whether the run completed and its error (None), and ``decisions_lost``: the times
    the controller found the policy not deciding (0 on the fast path, where it always decides;
    None: not known)."""
    return {"controller": controller, "policy": policy, "scenario": result.scenario.to_dict(),
            **result.summary(tolerance),
            "real_time_factor": round(result.duration / wall_time, 2) if wall_time > 0 and result.duration > 0
            else None,
            "wall_time": round(wall_time, 3), "completed": completed, "error": error,
            "decisions_lost": decisions_lost}

