"""Regenerate the classic HZD gait library (the paper's FROST baseline, in Python).

    scripts/optimize_gaits.py [--speeds 0.7,0.8,...] [--start 1.0] [--iterations 100]
                              [--workers 2] [--out DIR] [--validate 60] [--resume]
                              [--approach-from 0.9,1.2] [--approach-weight 5] [--refine]
                              [--friction-limit 0.6]

Speeds are solved by continuation outward from ``--start``: the first from a kinematic
seed (:mod:`rabbit_policy.gait_design.seed`), each next one warm-started from the nearest speed
already solved. Each result is then walked for ``--validate`` seconds; a gait that falls
or misses its speed by more than 5 % is re-optimised once with twice the generations,
and if it still fails it goes to ``--out/rejected/`` (not shipped) instead. One JSON
file per gait goes to ``--out`` (default: the packaged library, ``rabbit_policy/gaits``).

``--approach-from`` adds convergence to the objective: how fast the gait pulls the robot
to its speed from the library gaits of the given speeds (see
:mod:`rabbit_policy.gait_design.optimization`). ``--refine`` starts each listed speed from the
gait already in ``--out`` instead of from its neighbour. The shipped 1.4 and 1.5 m/s
gaits were refined this way (the README's "gait library" section has the commands).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser
from rabbit_msgs_py.environment import ensure_localhost_discovery
from rabbit_policy.parallel import add_backend_arguments, open_backend


def parse_speeds(text: str) -> list[float]:
    speeds = sorted({round(float(s), 3) for s in text.split(",") if s.strip()})
    if not speeds or any(not 0.1 <= s <= 3.0 for s in speeds):
        raise argparse.ArgumentTypeError("speeds must be a comma-separated list in [0.1, 3] m/s")
    return speeds


def design(argv: list[str] | None = None) -> int:
    ensure_localhost_discovery()
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--speeds", type=parse_speeds, default=parse_speeds("0.7,0.8,0.9,1.0,1.1,1.2,1.3,1.4,1.5"))
    parser.add_argument("--start", type=float, default=1.0, help="speed solved first (m/s)")
    parser.add_argument("--iterations", "--generations", type=int, default=100, dest="iterations",
                        help="CMA-ES generations per gait (as train.py's --iterations)")
    add_backend_arguments(parser)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--validate", type=float, default=60.0, help="validation walk (s)")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--resume", action="store_true",
                        help="keep gaits in --out that passed validation; solve only the other speeds")
    parser.add_argument("--friction-limit", type=float, default=None,
                        help="stance-foot |F_t|/F_n the gait is designed to stay under (the model's floor has "
                             "0.8; default: GaitProblem.friction_limit, the shipped library's); lower it to "
                             "design for a slippery floor")
    parser.add_argument("--approach-weight", type=float, default=5.0,
                        help="cost per metre of approach shortfall (default %(default)s)")
    parser.add_argument("--approach-from", type=parse_speeds, default=[],
                        help="also minimise the time to reach each speed from these library speeds")
    parser.add_argument("--refine", action="store_true",
                        help="start each speed from its existing gait in --out")
    args = parser.parse_args(argv)
    if args.friction_limit is not None and not 0.05 <= args.friction_limit <= 2.0:
        parser.error(f"--friction-limit must be in [0.05, 2], got {args.friction_limit}")
    backend = open_backend(parser, args)
    try:
        return _optimize(args, backend)
    finally:
        backend.close()


def _optimize(args, backend) -> int:
    from rabbit_hzd_controller.gait import Gait
    from rabbit_policy.experiment.loop import walk_gait
    from rabbit_policy.gait_design.optimization import GaitProblem, gait_to_decision, optimize_gait
    from rabbit_policy.gait_design.seed import SeedPattern, seed_free_alpha
    from rabbit_policy.runtime.gait_library import packaged_gait_dir
    from rabbit_policy.gait_design.optimization import KD_SCALE

    out = args.out or packaged_gait_dir()
    out.mkdir(parents=True, exist_ok=True)

    order = sorted(args.speeds, key=lambda s: (abs(s - args.start), s))
    solved: dict[float, Gait] = {}
    report = []
    if args.resume:
        for path in sorted(out.glob("gait_*.json")):
            gait = Gait.load(path)
            if gait.info.get("validation", {}).get("passed"):
                solved[round(gait.speed, 3)] = gait
                print(f"[{gait.speed:.2f} m/s] kept {path.name}", flush=True)
    for speed in order:
        if speed in solved:
            continue
        problem = GaitProblem(speed=speed, approach_from=tuple(args.approach_from),
                              approach_weight=args.approach_weight)
        if args.friction_limit is not None:
            problem = replace(problem, friction_limit=args.friction_limit)
        existing = out / f"gait_{speed:.2f}.json"
        if args.refine and existing.is_file():
            x0 = gait_to_decision(Gait.load(existing))
            origin = f"refining {existing.name}"
        elif solved:
            nearest = min(solved, key=lambda s: abs(s - speed))
            x0 = gait_to_decision(solved[nearest])
            origin = f"warm start from {nearest:.2f} m/s"
        else:
            pattern = SeedPattern(step_length=0.4, hip_height=0.76, torso_pitch=0.05)
            x0 = np.concatenate([seed_free_alpha(pattern), [60.0 / KD_SCALE]])
            origin = "kinematic seed"
        print(f"[{speed:.2f} m/s] optimising ({origin})", flush=True)
        gait, check, attempts, wall = None, None, 0, 0.0
        for generations in (args.iterations, 2 * args.iterations):
            attempts += 1
            result = optimize_gait(problem, x0, max_generations=generations, backend=backend,
                                   seed=args.seed, log=lambda s: print(s, flush=True))
            wall += result.wall_time
            gait = result.gait
            check = walk_gait(gait, args.validate)
            mean = check.summary()["mean_speed"]
            ok = mean is not None and abs(mean - speed) <= 0.05 * speed
            print(f"[{speed:.2f} m/s] cost {result.evaluation.cost:.3f}, {args.validate:.0f} s walk: "
                  f"fell={check.fell} stalled={check.stalled} mean speed {mean} -> {'ok' if ok else 'FAILED'}",
                  flush=True)
            if ok:
                break
            x0 = gait_to_decision(gait)
        assert gait is not None and check is not None
        summary = check.summary()
        validation = {**{k: summary[k] for k in ("fell", "stalled", "duration", "steps", "mean_speed", "peak_torque")},
                      "passed": summary["mean_speed"] is not None and abs(summary["mean_speed"] - speed) <= 0.05 * speed}
        info = dict(gait.info, validation=validation, attempts=attempts, wall_time_s=wall)
        gait = Gait(alpha=gait.alpha, kd=gait.kd, kp=gait.kp, speed=gait.speed,
                    step_length=gait.step_length, step_period=gait.step_period, cost=gait.cost, info=info)
        if validation["passed"]:
            gait.save(out / f"gait_{speed:.2f}.json")
            solved[speed] = gait
        else:  # kept for inspection, outside the shipped library
            (out / "rejected").mkdir(exist_ok=True)
            gait.save(out / "rejected" / f"gait_{speed:.2f}.json")
        report.append({"speed": speed, "cost": gait.cost, "step_length": gait.step_length,
                       "step_period": gait.step_period, "kd": gait.kd,
                       **{f"validation_{k}": v for k, v in validation.items()}})
    print(strict_json.dumps(sorted(report, key=lambda r: r["speed"]), indent=1))
    return 0 if all(r["validation_passed"] for r in report) else 1


def main(argv: list[str] | None = None) -> int:
    """:func:`design`, then the total wall time on stderr."""
    start = time.perf_counter()
    code = design(argv)
    print(f"total wall time {time.perf_counter() - start:.0f} s", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
