"""The paper's section IV as data: speed tracking, limit cycles, Poincaré stability and
push recovery of classic HZD and HZD-RL, on the one ROS-free closed loop (:mod:`rabbit_policy.experiment.loop`).

Every experiment returns plain JSON-ready dicts (what ``results.json`` holds) and, where
a figure needs more than that, the walks themselves; :mod:`.figures` draws them and
``scripts/evaluate.py`` runs it all. The two controllers are policies
(:mod:`rabbit_policy.runtime.policies`): ``classic`` = the gait library (nearest gait to the commanded speed,
no speed feedback), ``learned`` = the HZD-RL network.

Definitions used in the tables:

* filtered speed: the hip's forward speed (world x, m/s) averaged over the last
  ``filter_window`` s (a causal moving average; one step takes 0.4-0.7 s);
* mean error of a segment: mean |filtered - commanded| over the segment (m/s);
* settling time: from the change of command to the moment after which the filtered
  speed stays within ``tolerance`` of the command until the segment ends (s; None if it
  never settles);
* reach time: the one definition (:mod:`rabbit_policy.experiment.result`): the first whole step whose
  mean speed is within ``tolerance``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable

import numpy as np

from rabbit_hzd_controller.controller import Leg

from rabbit_policy.evaluation.push_recovery import (PUSH_SCENARIOS, Neighbourhood, PushScenario, RepeatedConfig,
                                                    SweepConfig, impulse_sweep, neighbourhood_outcomes, push_trial,
                                                    repeated_pushes, scenario_table)
from rabbit_policy.evaluation.statistics import mcnemar_exact, rate
from rabbit_policy.evaluation.robustness import RobustnessConfig
from rabbit_policy.evaluation.stability import STANCE_JOINTS, analyse_stability
from rabbit_policy.experiment.loop import walk as run_walk
from rabbit_policy.experiment.result import WalkResult
from rabbit_policy.experiment.scenario import Push, Scenario, Schedule
from rabbit_policy.runtime.policies import Policy
from rabbit_sim.physics.model import ModelOptions

MapFn = Callable[[Callable, Iterable], Iterable]

POINCARE_SEEDS = (0, 1, 2)
"""Perturbation seeds of every Poincaré verdict (check 6, ``evaluate.py``'s test). The largest
|lambda| of one analysis moves by 0.1-0.25 from seed to seed (classic at 1.0 m/s: 0.83-0.98
over seeds 0-3 with 400 samples, 0.77-0.91 with 1600; docs/learning.md, 2026-11-26), and
another machine's rounding acts as another seed: a verdict is the median of three."""


@dataclass(frozen=True)
class EvaluationConfig:
    """What ``scripts/evaluate.py`` runs (speeds m/s, times s)."""

    tracking_schedule: Schedule = ((0.0, 0.8), (6.0, 1.2), (12.0, 0.9), (18.0, 1.5), (24.0, 0.7))
    tracking_duration: float = 30.0
    filter_window: float = 0.75  # s: the longest step (0.73 s at 0.7 m/s), so the in-step swing averages out
    tolerance: float = 0.05
    portrait_speeds: tuple[float, ...] = (0.7, 1.0, 1.3)
    portrait_duration: float = 15.0
    portrait_push: Push = Push(1.0, 60.0, 0.1)
    poincare_speeds: tuple[float, ...] = (0.7, 1.0, 1.3)
    poincare_samples: int = 400
    poincare_seeds: tuple[int, ...] = POINCARE_SEEDS  # one analysis each; the verdict is their median
    push_speed: float = 1.0
    push_duration: float = 10.0
    scenarios: tuple[PushScenario, ...] = PUSH_SCENARIOS
    neighbourhood: Neighbourhood | None = field(default_factory=Neighbourhood)
    sweep: SweepConfig | None = field(default_factory=SweepConfig)
    repeated: RepeatedConfig | None = field(default_factory=RepeatedConfig)
    video_scenarios: tuple[str, ...] = ("small_backward", "large_backward")
    video_fps: float = 10.0
    video_size: tuple[int, int] = (320, 240)
    series_rate: float = 50.0  # Hz of the time series stored in results.json
    robustness: RobustnessConfig | None = field(default_factory=RobustnessConfig)

    @classmethod
    def quick(cls) -> EvaluationConfig:
        """A short version (about 25 s on two cores) for tests and a first look."""
        return cls(tracking_schedule=((0.0, 0.9), (4.0, 1.2)), tracking_duration=8.0,
                   portrait_speeds=(1.0,), portrait_duration=4.0, poincare_speeds=(1.0,),
                   poincare_samples=30, push_duration=7.0,
                   neighbourhood=Neighbourhood(shifts=(-0.05, 0.0, 0.05), speeds=(1.0,), duration=7.0),
                   sweep=SweepConfig(impulses=(3.0, 12.0), push_times=(3.0,), horizon=2.0),
                   repeated=RepeatedConfig(impulses=((1.0, (3.0, 40.0)),), first_times=(2.0,), count=2,
                                           horizon=5.0),
                   video_scenarios=("large_backward",), video_fps=5.0, video_size=(160, 120),
                   robustness=RobustnessConfig.quick())

    def __post_init__(self) -> None:
        names = {s.name for s in self.scenarios}
        unknown = [v for v in self.video_scenarios if v not in names]
        if unknown:
            raise ValueError(f"video_scenarios {unknown} are not among the push scenarios {sorted(names)}")

    def to_dict(self) -> dict:
        return {"tracking_schedule": [list(s) for s in self.tracking_schedule],
                "tracking_duration_s": self.tracking_duration, "filter_window_s": self.filter_window,
                "tolerance_mps": self.tolerance, "portrait_speeds": list(self.portrait_speeds),
                "portrait_duration_s": self.portrait_duration,
                "portrait_push": {"time_s": self.portrait_push.time, "force_x_N": self.portrait_push.force_x,
                                  "duration_s": self.portrait_push.duration},
                "poincare_speeds": list(self.poincare_speeds), "poincare_samples": self.poincare_samples,
                "poincare_seeds": list(self.poincare_seeds),
                "push_speed": self.push_speed, "push_duration_s": self.push_duration,
                "scenarios": [s.to_dict() for s in self.scenarios],
                "neighbourhood": None if self.neighbourhood is None else self.neighbourhood.to_dict(),
                "sweep": None if self.sweep is None else {
                    "impulses_Ns": list(self.sweep.impulses), "push_duration_s": self.sweep.duration,
                    "push_times_s": list(self.sweep.push_times), "horizon_s": self.sweep.horizon},
                "repeated": None if self.repeated is None else self.repeated.to_dict(),
                "video_scenarios": list(self.video_scenarios), "video_fps": self.video_fps,
                "video_size": list(self.video_size),
                "robustness": None if self.robustness is None else self.robustness.to_dict()}


# ------------------------------------------------------------------ signals
def filtered_speed(times: np.ndarray, speed: np.ndarray, window: float) -> np.ndarray:
    """Causal moving average of ``speed`` over the last ``window`` s (shorter at the start)."""
    if not window > 0:
        raise ValueError("window must be > 0")
    times, speed = np.asarray(times, dtype=float), np.asarray(speed, dtype=float)
    cumulative = np.concatenate(([0.0], np.cumsum(speed)))
    first = np.searchsorted(times, times - window + 1e-12)
    last = np.arange(1, len(times) + 1)
    return (cumulative[last] - cumulative[first]) / (last - first)


def settling_time(times: np.ndarray, value: np.ndarray, target: float, start: float, end: float,
                  tolerance: float) -> float | None:
    """Time from ``start`` until ``value`` stays within ``tolerance`` of ``target`` up to
    ``end`` (s); None if it is outside at the end (or there are no samples)."""
    mask = (times > start) & (times <= end + 1e-9)
    if not mask.any():
        return None
    outside = np.abs(value[mask] - target) > tolerance
    if outside[-1]:
        return None
    seg_times = times[mask]
    if not outside.any():
        return 0.0
    last_outside = int(np.nonzero(outside)[0][-1])
    return float(seg_times[last_outside + 1] - start)


def downsample(times: np.ndarray, rate: float, *series: np.ndarray) -> list[list[float]]:
    """``[times, *series]`` at about ``rate`` Hz, rounded for a compact JSON."""
    dt = float(times[1] - times[0]) if len(times) > 1 else 1.0
    stride = max(1, int(round(1.0 / (rate * dt))))
    return [np.round(np.asarray(s)[::stride], 4).tolist() for s in (times, *series)]


# ------------------------------------------------------------------ speed tracking
def tracking_segments(walk: WalkResult, schedule: Schedule, duration: float, window: float,
                      tolerance: float) -> list[dict]:
    """Per commanded segment: mean |filtered error| (m/s), signed mean error over the
    second half, settling time (s) and reach time (s)."""
    filtered = filtered_speed(walk.times, walk.hip_speed, window)
    ends = [t for t, _ in schedule[1:]] + [duration]
    rows = []
    for (start, speed), end in zip(schedule, ends):
        mask = (walk.times > start) & (walk.times <= end + 1e-9)
        half = mask & (walk.times > 0.5 * (start + end))
        complete = not walk.failed or walk.duration >= end
        rows.append({
            "start": start, "end": end, "speed": speed,
            "mean_abs_error": float(np.mean(np.abs(filtered[mask] - speed))) if mask.any() else None,
            "mean_error_second_half": float(np.mean(filtered[half] - speed)) if half.any() else None,
            "settling_time": settling_time(walk.times, filtered, speed, start, end, tolerance) if complete else None,
            "reach_time": walk.reach_time(start, end, speed, tolerance),
        })
    return rows


def speed_tracking(policy: Policy, config: EvaluationConfig, model: ModelOptions = ModelOptions()) -> tuple[dict, WalkResult]:
    """Walk the tracking schedule; returns (results, walk)."""
    walk = run_walk(policy, Scenario(schedule=config.tracking_schedule, model=model), config.tracking_duration)
    filtered = filtered_speed(walk.times, walk.hip_speed, config.filter_window)
    t, v, vd = downsample(walk.times, config.series_rate, filtered, walk.desired_speed)
    return {"policy": policy.name, **walk.outcome(),
            "segments": tracking_segments(walk, config.tracking_schedule, config.tracking_duration,
                                          config.filter_window, config.tolerance),
            "series": {"time_s": t, "filtered_speed_mps": v, "desired_speed_mps": vd}}, walk


# ------------------------------------------------------------------ limit cycles
def post_touchdown_states(walk: WalkResult, delay: float = 0.02) -> np.ndarray:
    """Stance-relative joint state ``delay`` s after every touchdown of a ``record_state``
    walk: rows (stance hip, stance knee, swing hip, swing knee (rad), their rates
    (rad/s)). Not at the touchdown tick itself: whether that sample is before or after
    the impact's velocity jump depends on the tick grid, a noise that would swamp the
    convergence."""
    if walk.qpos is None or walk.stance is None:
        raise ValueError("the walk was not recorded with record_state=True")
    dt = float(walk.times[1] - walk.times[0]) if len(walk.times) > 1 else 1e-3
    offset = int(round(delay / dt))
    switches = np.nonzero(np.diff(walk.stance.astype(int)))[0] + 1 + offset
    rows = []
    for i in switches[switches < len(walk.times)]:
        joints = list(STANCE_JOINTS[Leg(int(walk.stance[i]))])
        rows.append(np.concatenate((walk.qpos[i, joints], walk.qvel[i, joints])))
    return np.array(rows).reshape(-1, 8)


def convergence(states: np.ndarray, tail: int = 6, rate_scale: float = 10.0, band: float = 5.0) -> dict:
    """Distance of each step's state from the mean of the last ``tail`` ones (rates
    divided by ``rate_scale`` s^-1 so that rad and rad/s weigh alike): a converging
    limit cycle shows a shrinking sequence down to the walk's own step-to-step jitter
    (the median of the last ``tail`` distances). ``settled_step``: the first step from
    which the distance stays within ``band`` x that jitter (None if only the tail does)."""
    if len(states) <= tail:
        return {"distances": [], "jitter": None, "settled_step": None}
    reference = states[-tail:].mean(axis=0)
    weights = np.array([1.0] * 4 + [1.0 / rate_scale] * 4)
    distances = np.linalg.norm((states - reference) * weights, axis=1)
    jitter = float(np.median(distances[-tail:]))
    above = np.nonzero(distances > band * jitter)[0]
    settled = int(above[-1] + 1) if above.size else 0
    return {"distances": np.round(distances, 5).tolist(), "jitter": round(jitter, 5),
            "settled_step": settled if settled < len(distances) - tail else None}


def limit_cycle(policy: Policy, speed: float, config: EvaluationConfig, model: ModelOptions = ModelOptions()) -> tuple[dict, WalkResult]:
    """A walk at ``speed`` perturbed once by ``config.portrait_push``: the phase
    portraits' data and the touchdown-to-touchdown convergence."""
    walk = run_walk(policy, Scenario.constant(speed, pushes=(config.portrait_push,), model=model),
                    config.portrait_duration, record_state=True)
    return {"policy": policy.name, "speed": speed, **walk.outcome(),
            "steps": walk.steps, **convergence(post_touchdown_states(walk))}, walk


# ------------------------------------------------------------------ Poincaré
def median_analysis(analyses: list[dict]) -> dict:
    """One verdict from the analyses of one speed under several perturbation seeds (pure):
    the analysis whose largest |lambda| is the median (an odd count: a measured one), with
    ``largest_by_seed`` (the spread) added; the first ``{"error": ...}`` if any run found
    no cycle or failed."""
    if not analyses:
        raise ValueError("median_analysis needs at least one analysis")
    failed = [a for a in analyses if a.get("error") or a.get("largest") is None]
    if failed:
        return {**failed[0], "largest_by_seed": [a.get("largest") for a in analyses]}
    ranked = sorted(analyses, key=lambda a: a["largest"])
    return {**ranked[(len(ranked) - 1) // 2], "largest_by_seed": [a["largest"] for a in analyses]}


def _stability_job(job: tuple) -> dict:
    policy, speed, feedback, samples, model, *seed = job  # seed: the perturbations' (default 0)
    try:
        return analyse_stability(policy, speed, feedback, samples=samples, model=model, seed=seed[0] if seed else 0
                                 ).to_dict()
    except RuntimeError as exc:  # the cycle could not be found or too many perturbed runs failed
        return {"error": str(exc), "stable": False}


def seeded_analyses(cases: list[tuple[Policy, float, bool]], samples: int, model: ModelOptions,
                    seeds: tuple[int, ...] = POINCARE_SEEDS, map_fn: MapFn = map) -> list[dict]:
    """Per case (policy, speed m/s, speed feedback): the :func:`median_analysis` of its
    Poincaré analyses under each of ``seeds``, ``samples`` perturbed runs each."""
    jobs = [(policy, speed, feedback, samples, model, seed) for policy, speed, feedback in cases for seed in seeds]
    analyses = list(map_fn(_stability_job, jobs))
    n = len(seeds)
    return [median_analysis(analyses[i * n:(i + 1) * n]) for i in range(len(cases))]


def poincare(controllers: dict[str, tuple[Policy, bool]], config: EvaluationConfig, model: ModelOptions = ModelOptions(),
             map_fn: MapFn = map) -> dict:
    """``{controller: {speed: analysis}}`` for ``controllers`` = name -> (policy, feedback), an
    analysis being the :func:`median_analysis` of ``config.poincare_seeds``' analyses."""
    keys = [(name, speed) for name in controllers for speed in config.poincare_speeds]
    analyses = seeded_analyses([(controllers[name][0], speed, controllers[name][1]) for name, speed in keys],
                               config.poincare_samples, model, config.poincare_seeds, map_fn)
    results: dict = {name: {} for name in controllers}
    for (name, speed), analysis in zip(keys, analyses):
        results[name][f"{speed:.2f}"] = analysis
    return results


# ------------------------------------------------------------------ pushes
def push_experiment(controllers: dict[str, Policy], config: EvaluationConfig, model: ModelOptions = ModelOptions()
                    ) -> tuple[dict, dict[str, dict[str, WalkResult]]]:
    """The push scenarios at ``config.push_speed`` for every controller: the who-fell
    table, speed series, and the walks (recorded, for the videos)."""
    walks = {name: {s.name: push_trial(policy, config.push_speed, s, config.push_duration, model,
                                       record_state=True)
                    for s in config.scenarios}
             for name, policy in controllers.items()}
    series = {}
    for name, by_scenario in walks.items():
        series[name] = {}
        for scenario, walk in by_scenario.items():
            t, v = downsample(walk.times, config.series_rate,
                              filtered_speed(walk.times, walk.hip_speed, config.filter_window))
            series[name][scenario] = {"time_s": t, "filtered_speed_mps": v}
    return {"speed": config.push_speed, "duration_s": config.push_duration,
            "scenarios": [s.to_dict() for s in config.scenarios],
            "table": scenario_table(walks, config.scenarios), "series": series}, walks


def scenario_rates(controllers: dict[str, Policy], config: EvaluationConfig, model: ModelOptions = ModelOptions(),
                   map_fn: MapFn = map) -> dict:
    """The push scenarios as rates over their neighbourhoods (:class:`~.push_recovery.Neighbourhood`):
    per controller and scenario the trials walked (``k`` of ``n``, 95 % interval) and every
    trial's outcome, and the learned controller against each other one on the same trials
    (McNemar's exact test)."""
    nb = config.neighbourhood
    if nb is None:
        return {}
    outcomes = {name: {s.name: neighbourhood_outcomes(policy, s, nb, model, map_fn) for s in config.scenarios}
                for name, policy in controllers.items()}
    paired = {}
    if "learned" in outcomes:
        paired = {s.name: {other: mcnemar_exact(outcomes["learned"][s.name], outcomes[other][s.name])
                           for other in outcomes if other != "learned"} for s in config.scenarios}
    return {"config": nb.to_dict(), "trials": [[speed, shift] for speed in nb.speeds for shift in nb.shifts],
            "rates": {name: {s: rate(o) for s, o in by.items()} for name, by in outcomes.items()},
            "paired_with_learned": paired, "outcomes": outcomes}


def repeated_push_table(controllers: dict[str, Policy], config: EvaluationConfig, model: ModelOptions = ModelOptions(),
                        map_fn: MapFn = map) -> dict:
    """Repeated pushes (:func:`~.push_recovery.repeated_pushes`) per controller."""
    if config.repeated is None:
        return {}
    return {name: repeated_pushes(policy, config.repeated, model, map_fn) for name, policy in controllers.items()}


def push_sweep(controllers: dict[str, Policy], config: EvaluationConfig, model: ModelOptions = ModelOptions(),
               map_fn: MapFn = map) -> dict:
    """Largest impulse survived, forward and backward, per controller."""
    if config.sweep is None:
        return {}
    return {name: {direction: impulse_sweep(policy, config.push_speed, sign, config.sweep, model, map_fn)
                   for direction, sign in (("forward", 1), ("backward", -1))}
            for name, policy in controllers.items()}

