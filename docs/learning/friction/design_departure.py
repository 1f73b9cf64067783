# Design probe (issue 37, friction 0.35): can a 1.4 or 1.5 m/s gait designed under a friction
# limit of 0.3 also be left for slower speeds? The gait design's objective (total_cost: effort,
# the penalties at --friction-limit 0.3, the approach from 0.9 and 1.1 m/s) plus a departure term
# scored as check 2 scores a change: classic HZD as shipped (the calibrated interpolation, a
# decision every 20 ticks) on a library with the candidate in it walks at the candidate's speed,
# the command drops to each target at two phases of a step, and each change costs 50 if it falls
# or stalls, else 5 x its shortfall (m: the integral of each step's distance from the target
# beyond 0.05 m/s over 6 s). CMA-ES (cma), 2 processes.
#   .venv/bin/python docs/learning/friction/design_departure.py SPEED BASE_DIR X0_GAIT OUT_GAIT [GENERATIONS]
# design_departure_150.log: 1.5 m/s from library_030 (base: library_030); _140.log: 1.4 m/s from
# library_030 (base: library_030 with the new 1.5); both in library_030_departure/, recalibrated
# (calibrate_030_departure.log) and validated 60 s as optimize_gaits does.
# BASE_DIR: the library the candidate joins (its calibration kept: stale for the candidate's
# pairs, exact at the library's own speeds, where these changes go).
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import cma
import numpy as np

from rabbit_hzd_controller.gait import Gait
from rabbit_policy.evaluation.robustness import phase_times
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.result import REACH_TOLERANCE
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.gait_design.optimization import (GaitProblem, decision_to_gait_params, evaluate, gait_to_decision,
                                                    total_cost)
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import CLASSIC_DECISION_PERIOD, LibraryPolicy, PeriodicPolicy
from rabbit_policy.runtime.speed_integral import decision_dt

TARGETS = (0.8, 1.0)
PHASES = (0.0, 0.5)
HORIZON = 6.0


def classic_with(candidate: Gait, base: GaitLibrary) -> PeriodicPolicy:
    gaits = tuple(candidate if abs(g.speed - candidate.speed) < 1e-9 else g for g in base.gaits)
    library = GaitLibrary(gaits, base.calibration)
    return PeriodicPolicy(LibraryPolicy(library, "interpolate", 0.0, decision_dt(CLASSIC_DECISION_PERIOD)),
                          CLASSIC_DECISION_PERIOD)


def departures(x: np.ndarray, problem: GaitProblem, base: GaitLibrary) -> tuple[float, list[str]]:
    alpha, kd = decision_to_gait_params(np.asarray(x, dtype=float), problem)
    policy = classic_with(Gait(alpha=tuple(alpha), kd=kd, kp=problem.kp, speed=problem.speed), base)
    times = phase_times(policy, problem.speed, 3.0, PHASES)
    if times is None:
        return 50.0 * len(TARGETS) * len(PHASES), ["did not walk"]
    cost, notes = 0.0, []
    for target in TARGETS:
        for change in times:
            r = walk(policy, Scenario(schedule=((0.0, problem.speed), (change, target))), change + HORIZON)
            if r.failed:
                cost += 50.0
                notes.append(f"{target}:{'fell' if r.fell else 'stalled'}")
                continue
            shortfall = sum(max(0.0, abs(v - target) - REACH_TOLERANCE) * (e - s)
                            for s, e, v in r.step_speeds() if s >= change - 1e-9)
            cost += 5.0 * shortfall
            reach = r.reach_time(change, r.end_time, target, REACH_TOLERANCE)
            notes.append(f"{target}:{'never' if reach is None else f'{reach:.2f}s'}")
    return cost, notes


def job(args) -> float:
    x, problem, base_dir = args
    base = GaitLibrary.load(base_dir)
    design = total_cost(x, problem)
    if design >= 1000.0:  # fell on its own
        return design
    return design + departures(x, problem, base)[0]


def main() -> None:
    speed, base_dir, x0_path, out = float(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
    generations = int(sys.argv[5]) if len(sys.argv) > 5 else 60
    problem = GaitProblem(speed=speed, friction_limit=0.3, approach_from=(0.9, 1.1))
    base = GaitLibrary.load(base_dir)
    x0 = gait_to_decision(Gait.load(x0_path))
    start = time.perf_counter()
    print(f"x0: design {total_cost(x0, problem):.3f}, departures {departures(x0, problem, base)}", flush=True)
    es = cma.CMAEvolutionStrategy(x0, 0.03, {"seed": 1, "maxiter": generations, "verbose": -9})
    with ProcessPoolExecutor(2) as pool:
        while not es.stop():
            xs = es.ask()
            es.tell(xs, list(pool.map(job, [(np.asarray(c), problem, base_dir) for c in xs])))
            if es.countiter % 5 == 0:
                print(f"gen {es.countiter} best {es.result.fbest:.3f} ({time.perf_counter() - start:.0f} s)", flush=True)
    best = np.asarray(es.result.xbest)
    ev = evaluate(best, problem)
    print(f"best: design {total_cost(best, problem):.3f} (max friction ratio {ev.max_friction_ratio:.2f}, "
          f"step {ev.step_length:.3f} m / {ev.step_period:.3f} s), departures {departures(best, problem, base)}",
          flush=True)
    alpha, kd = decision_to_gait_params(best, problem)
    Gait(alpha=tuple(alpha), kd=kd, kp=problem.kp, speed=speed, step_length=ev.step_length,
         step_period=ev.step_period, cost=ev.cost,
         info={"method": "docs/learning/friction/design_departure.py", "problem": {**problem.__dict__},
               "evaluation": {"max_friction_ratio": ev.max_friction_ratio, "penalties": ev.penalties}}).save(out)


if __name__ == "__main__":
    main()
