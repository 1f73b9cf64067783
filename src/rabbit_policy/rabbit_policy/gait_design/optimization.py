"""Classic HZD gait design: the Python stand-in for the paper's FROST baseline.

Method: direct (single) shooting on the MuJoCo model in closed loop with the very HZD
controller that later walks the gait, optimised with CMA-ES (the ``cma`` package).

Why shooting on MuJoCo rather than collocation on a rigid hybrid model (FROST, or
CasADi + IPOPT): the shipped gaits must walk in *this* simulator with *this* PD
controller, which has soft contacts, a torque-saturated PD law instead of
feedback linearisation, and no exact impact map. A gait optimised on a rigid
model would have to be re-tuned here anyway; shooting optimises what is then run.
CMA-ES needs no gradients through contact and copes with the objective's
discontinuities (falls, missed touchdowns). The price is compute: each candidate
is an ``horizon``-second closed-loop simulation (about 0.1 s of CPU).

Decision variables: the 20 free Bezier coefficients (the impact equalities hold by
construction) and Kd; Kp is fixed. ``p_plus``, ``p_minus`` follow from alpha
(:func:`rabbit_hzd_controller.phase.phase_bounds_from_alpha`).

Objective (per candidate, over the second half of the horizon, once the transient from
the initial state has died out):

* effort per step length: ``(1/L) * integral sum_j (u_j / u_max)^2 dt`` per step,
* plus penalties for constraint violations:
  - average speed off the design speed (the gait must *be* a ``speed`` m/s gait),
  - periodicity: step-to-step spread of step length and period (a converged limit
    cycle has none; impacts are part of the loop, so this is periodicity *through*
    impact),
  - friction cone: time-averaged excess of the stance-foot tangential/normal force
    ratio over ``friction_limit`` (below the simulator's 0.8 so there is margin),
  - unilateral contact: stance foot lifting off or both feet in the air,
  - swing-foot clearance below ``min_clearance`` in mid swing,
  - torque saturation (ticks at the 150 N m limit),
* optionally (``approach_from``) the time the gait takes to pull the robot to its speed
  from the library gait of a slower speed: the robot walks that gait, the candidate
  takes over at a touchdown, and the cost grows by ``approach_weight`` per metre of
  shortfall: the time integral of how far each step's mean speed is from the design
  speed beyond ``approach_tolerance`` (the learning issue's "new speed reached" band).
  A gait can be a fine periodic orbit yet converge to it slowly; this term makes
  convergence part of the design (measured: the 1.5 m/s gait designed without it never
  came within 0.05 m/s in 8 s from 0.9 m/s; refined with it, 2.4 s),
* and a fall penalty that makes any fall worse than any walk, graded by how long it
  walked so the optimiser can climb out of falling regions.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable

import mujoco
import numpy as np

from rabbit_hzd_controller.alpha import N_FREE, expand_alpha
from rabbit_hzd_controller.controller import ControllerConfig
from rabbit_hzd_controller.gait import Gait
from rabbit_policy.experiment.loop import ClosedLoop, walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.parallel import LocalBackend
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import GaitCommand, LibraryPolicy
from rabbit_sim.physics.model import ModelOptions, load_model

KD_SCALE = 100.0
"""Kd enters the decision vector divided by this, so all variables are O(0.1..1)."""


@dataclass(frozen=True)
class GaitProblem:
    """One gait design problem. Speeds m/s, lengths m, times s, torques N m."""

    speed: float
    kp: float = ControllerConfig.kp
    horizon: float = 10.0
    friction_limit: float = 0.6
    min_clearance: float = 0.02
    torque_limit: float = 150.0
    kd_bounds: tuple[float, float] = (0.0, 300.0)
    speed_tolerance: float = 0.01
    model_variant: str = "paper"
    approach_from: tuple[float, ...] = ()
    approach_weight: float = 5.0
    approach_tolerance: float = 0.05
    approach_settle: float = 3.0
    approach_horizon: float = 8.0
    approach_blend_phase: float = 0.0  # the approach switch: once per step, no blend (as the gaits were designed)


@dataclass
class GaitEvaluation:
    """What one closed-loop rollout of a candidate measured. ``fell`` is also true for a
    stall (no steady stepping in the second half): both rank below any walk."""

    cost: float
    fell: bool
    walked_time: float
    mean_speed: float = float("nan")
    step_length: float = float("nan")
    step_period: float = float("nan")
    effort: float = float("nan")
    max_friction_ratio: float = 0.0
    min_clearance: float = float("inf")
    saturated_fraction: float = 0.0
    periodicity: float = float("nan")
    liftoff: float = 0.0
    peak_torque: float = 0.0
    penalties: dict[str, float] = field(default_factory=dict)


def decision_to_gait_params(x: np.ndarray, problem: GaitProblem) -> tuple[np.ndarray, float]:
    """Decision vector -> (24-vector alpha, Kd)."""
    alpha = expand_alpha(x[:N_FREE])
    lo, hi = problem.kd_bounds
    kd = float(np.clip(x[N_FREE] * KD_SCALE, lo, hi))
    return alpha, kd


class _Metrics:
    """Per-tick figures of a candidate's walk over the second half of the horizon (an
    observer of the closed loop): effort, peak torque, saturation, friction-cone excess,
    stance-foot lift-off and mid-swing clearance."""

    def __init__(self, model: mujoco.MjModel, problem: GaitProblem, half: int) -> None:
        self.model, self.problem, self.half = model, problem, half
        self.feet = (model.site("left_foot").id, model.site("right_foot").id)
        self.foot_geoms = (model.geom("left_foot").id, model.geom("right_foot").id)
        self.dt = model.opt.timestep
        self.effort = self.peak = self.max_ratio = self.slip = self.liftoff = 0.0
        self.saturated = 0
        self.min_clear = float("inf")
        self.force = np.zeros(6)

    def observe(self, loop: ClosedLoop, torques) -> None:
        i = loop.ticks - 1
        if i < self.half:
            return
        limit, dt, problem = self.problem.torque_limit, self.dt, self.problem
        for tq in torques:
            self.effort += (tq / limit) ** 2 * dt
            self.peak = max(self.peak, abs(tq))
            if abs(tq) >= limit:
                self.saturated += 1
        data, controller = loop.data, loop.controller
        stance = int(controller.stance)
        stance_z = data.site_xpos[self.feet[stance]][2]
        swing_z = data.site_xpos[self.feet[1 - stance]][2]
        if stance_z > 0.005:
            self.liftoff += stance_z * dt
        if 0.25 <= controller.tau <= 0.75 and swing_z < self.min_clear:
            self.min_clear = float(swing_z)
        if i % 4 == 0:
            for c in range(data.ncon):
                con = data.contact[c]
                if con.geom1 == self.foot_geoms[stance] or con.geom2 == self.foot_geoms[stance]:
                    mujoco.mj_contactForce(self.model, data, c, self.force)
                    if self.force[0] > 1.0:
                        ratio = math.hypot(self.force[1], self.force[2]) / self.force[0]
                        self.max_ratio = max(self.max_ratio, ratio)
                        self.slip += max(0.0, ratio - problem.friction_limit) * 4 * dt


def evaluate(x: np.ndarray, problem: GaitProblem, model: mujoco.MjModel | None = None) -> GaitEvaluation:
    """Roll out the candidate ``x`` from a state on its own gait and score it."""
    model = model or load_model(ModelOptions(problem.model_variant))
    alpha, kd = decision_to_gait_params(np.asarray(x, dtype=float), problem)
    try:
        loop = ClosedLoop(Scenario.constant(problem.speed, model=ModelOptions(problem.model_variant)),
                          start=GaitCommand(tuple(alpha), kd), kp=problem.kp, model=model)
    except (ValueError, ZeroDivisionError, OverflowError):
        return GaitEvaluation(cost=1e4, fell=True, walked_time=0.0)
    data = loop.data
    qpos = data.qpos.tolist()
    if not all(math.isfinite(v) for v in qpos + data.qvel.tolist()) or abs(qpos[2]) > 0.5:
        return GaitEvaluation(cost=1e4, fell=True, walked_time=0.0)

    n = int(round(problem.horizon / model.opt.timestep))
    half = n // 2
    metrics = _Metrics(model, problem, half)
    loop.observer = metrics.observe
    fell = loop.run(max_ticks=n)
    td_times = [td.time for td in loop.touchdowns]
    td_x = [td.foot_x for td in loop.touchdowns]
    x_half = float(loop.result().hip_x[half]) if loop.ticks > half else 0.0
    effort, peak, saturated = metrics.effort, metrics.peak, metrics.saturated
    max_ratio, slip, min_clear, liftoff = metrics.max_ratio, metrics.slip, metrics.min_clear, metrics.liftoff
    dt = model.opt.timestep
    walked = loop.time
    if fell or len([t for t in td_times if t >= half * dt]) < 3:
        # Any fall, or a stall (no steady stepping), costs more than any walk; walking
        # longer and further is better, so the optimizer can climb out of these regions.
        progress = float(data.qpos[0] - qpos[0]) / (problem.speed * problem.horizon)
        cost = 1000.0 + 500.0 * (1.0 - walked / problem.horizon) + 200.0 * max(0.0, 1.0 - progress)
        return GaitEvaluation(cost=cost, fell=True, walked_time=walked)

    late = [(t, px) for t, px in zip(td_times, td_x) if t >= half * dt]
    times = np.array([t for t, _ in late])
    xs = np.array([px for _, px in late])
    periods = np.diff(times)
    lengths = np.diff(xs)
    step_length = float(np.mean(lengths))
    step_period = float(np.mean(periods))
    mean_speed = (float(data.qpos[0]) - x_half) / (walked - half * dt)
    periodicity = float(np.std(periods) / step_period + np.std(lengths) / max(step_length, 1e-3))
    steps = max(len(periods), 1)
    effort_per_step = effort / steps / max(step_length, 1e-3)
    rel_err = abs(mean_speed - problem.speed) / problem.speed
    penalties = {
        "speed": 200.0 * rel_err**2 + 1e5 * max(0.0, rel_err - problem.speed_tolerance) ** 2,
        "periodicity": 20.0 * periodicity,
        "friction": 1000.0 * slip / (walked - half * dt),
        "liftoff": 1e4 * liftoff,
        "clearance": 1e3 * max(0.0, problem.min_clearance - min_clear),
        "saturation": 10.0 * saturated / max(1, 4 * (n - half)),
        "step_length": 100.0 * max(0.0, 0.2 - step_length),
    }
    cost = effort_per_step + sum(penalties.values())
    return GaitEvaluation(
        cost=float(cost),
        fell=False,
        walked_time=walked,
        mean_speed=mean_speed,
        step_length=step_length,
        step_period=step_period,
        effort=effort_per_step,
        max_friction_ratio=max_ratio,
        min_clearance=min_clear,
        saturated_fraction=saturated / max(1, 4 * (n - half)),
        periodicity=periodicity,
        liftoff=liftoff,
        peak_torque=peak,
        penalties=penalties,
    )


@dataclass(frozen=True)
class Approach:
    """How a candidate pulled the robot to its speed from a slower gait: ``shortfall``
    (m) = the integral over the steps after the switch of max(0, |step mean speed -
    speed| - tolerance) dt, a smooth measure of slow convergence; ``reach_time`` (s) to
    the first step within the tolerance (None: not within the horizon); ``fell``."""

    shortfall: float
    reach_time: float | None
    fell: bool


def approach(x: np.ndarray, problem: GaitProblem, start: Gait) -> Approach:
    """Walk ``approach_settle`` s on the ``start`` gait at its speed, then the candidate
    ``x`` from the next touchdown on, for ``approach_horizon`` s."""
    alpha, kd = decision_to_gait_params(np.asarray(x, dtype=float), problem)
    candidate = Gait(alpha=tuple(alpha), kd=kd, kp=problem.kp, speed=problem.speed)
    policy = LibraryPolicy(GaitLibrary.from_gaits([start, candidate]), "nearest")
    switch = problem.approach_settle
    schedule = ((0.0, start.speed), (switch, problem.speed))
    horizon = problem.approach_horizon
    try:
        result = walk(policy, Scenario(schedule=schedule, model=ModelOptions(problem.model_variant)), switch + horizon,
                      controller=ControllerConfig(blend_phase=problem.approach_blend_phase))
    except (ValueError, ZeroDivisionError, OverflowError):
        return Approach(problem.speed * horizon, None, True)
    if result.failed:  # fell or stalled: graded by how long it walked after the switch
        walked = max(0.0, min(horizon, (result.fall_time or result.stall_time or 0.0) - switch))
        return Approach(problem.speed * (2.0 * horizon - walked), None, True)
    shortfall, previous = 0.0, 0.0
    for start, end, speed in result.step_speeds():
        if start >= switch - 1e-9:
            error = abs(speed - problem.speed) - problem.approach_tolerance
            shortfall += max(0.0, error) * (end - start)
        previous = end
    shortfall += max(0.0, problem.speed - problem.approach_tolerance - result.mean_speed(previous)) * (
        result.end_time - previous)  # the unfinished last step, if still short
    reach = result.reach_time(switch, result.end_time, problem.speed, problem.approach_tolerance)
    return Approach(shortfall, reach, False)


_START_GAITS: dict[float, Gait] = {}


def _start_gait(speed: float) -> Gait:
    """The packaged library's gait nearest to ``speed`` (cached per process)."""
    if speed not in _START_GAITS:
        _START_GAITS[speed] = GaitLibrary.load().nearest(speed)
    return _START_GAITS[speed]


def approach_cost(x: np.ndarray, problem: GaitProblem) -> tuple[float, dict[float, Approach]]:
    """The ``approach_from`` term of the objective (``approach_weight`` per metre of
    shortfall, a fall or stall costs more than any walk, less the longer it walked after the switch) and what each start speed measured."""
    results = {speed: approach(x, problem, _start_gait(speed)) for speed in problem.approach_from}
    return problem.approach_weight * sum(r.shortfall for r in results.values()), results


def total_cost(x: np.ndarray, problem: GaitProblem, model: mujoco.MjModel | None = None) -> float:
    """:func:`evaluate`'s cost plus, for a candidate that walks, :func:`approach_cost`."""
    evaluation = evaluate(x, problem, model)
    if evaluation.fell or not problem.approach_from:
        return evaluation.cost
    return evaluation.cost + approach_cost(x, problem)[0]


def _evaluate_cost(args: tuple[np.ndarray, GaitProblem]) -> float:
    x, problem = args
    return total_cost(x, problem, _worker_model(problem.model_variant))


_MODELS: dict[str, mujoco.MjModel] = {}


def _worker_model(variant: str) -> mujoco.MjModel:
    """One compiled model per worker process and variant."""
    if variant not in _MODELS:
        _MODELS[variant] = load_model(variant)
    return _MODELS[variant]


@dataclass
class OptimizationResult:
    gait: Gait
    evaluation: GaitEvaluation
    evaluations: int
    generations: int
    wall_time: float


def optimize_gait(
    problem: GaitProblem,
    x0: np.ndarray,
    sigma0: float = 0.03,
    max_generations: int = 120,
    popsize: int | None = None,
    seed: int = 1,
    workers: int = 1,
    log: Callable[[str], None] | None = None,
    backend=None,
) -> OptimizationResult:
    """Minimise :func:`evaluate` over the decision vector with CMA-ES from ``x0``; the
    candidates of a generation are evaluated on ``backend`` (a :mod:`rabbit_policy.parallel`
    backend; None: a local pool of ``workers`` processes, started and stopped here)."""
    import cma  # imported here: only the optimizer needs it

    start = time.perf_counter()
    options: dict[str, Any] = {
        "seed": seed,
        "maxiter": max_generations,
        "verbose": -9,
        "tolfun": 1e-6,
    }
    if popsize:
        options["popsize"] = popsize
    es = cma.CMAEvolutionStrategy(np.asarray(x0, dtype=float), sigma0, options)
    own = backend is None
    backend = LocalBackend(workers) if own else backend
    try:
        while not es.stop():
            candidates = es.ask()
            costs = backend.map(_evaluate_cost, [(np.asarray(c), problem) for c in candidates])
            es.tell(candidates, costs)
            if log and es.countiter % 10 == 0:
                log(f"  v={problem.speed:.2f} gen {es.countiter:4d} best {es.result.fbest:10.4f}")
    finally:
        if own:
            backend.close()
    best = np.asarray(es.result.xbest)
    evaluation = evaluate(best, problem, _worker_model(problem.model_variant))
    alpha, kd = decision_to_gait_params(best, problem)
    approach_info: dict[str, Any] = {}
    if problem.approach_from:
        term, measured = approach_cost(best, problem)
        approach_info = {"approach": {"cost": term, **{f"from_{s:.2f}": asdict(a) for s, a in measured.items()}}}
    gait = Gait(
        alpha=tuple(alpha),
        kd=kd,
        kp=problem.kp,
        speed=problem.speed,
        step_length=evaluation.step_length,
        step_period=evaluation.step_period,
        cost=evaluation.cost,
        info={
            "method": "CMA-ES shooting on the MuJoCo closed loop",
            "problem": asdict(problem),
            "evaluation": {k: v for k, v in asdict(evaluation).items()},
            "evaluations": int(es.countevals),
            "generations": int(es.countiter),
            **approach_info,
        },
    )
    return OptimizationResult(
        gait=gait,
        evaluation=evaluation,
        evaluations=int(es.countevals),
        generations=int(es.countiter),
        wall_time=time.perf_counter() - start,
    )


def gait_to_decision(gait: Gait) -> np.ndarray:
    """Inverse of :func:`decision_to_gait_params` (to warm-start from a gait)."""
    return np.concatenate([gait.free, [gait.kd / KD_SCALE]])
