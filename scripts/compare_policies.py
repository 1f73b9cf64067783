#!/usr/bin/env python3
"""Checks 1-6 (the learning issue's broad acceptance) on several learned policies against one
classic reference, measured once: the ablation's table.

    scripts/compare_policies.py docs/learning/a_es_moderate/best.pt docs/learning/b_es_moderate/best.pt \\
        --names a b [--classic-integral 0.2] [--quick] [--workers 2] [--out runs/ablation_checks.json]

For classic HZD (the calibrated library, every 20 ticks), each policy file and each
``--classic-integral`` gain (classic HZD with Westervelt's event-based speed integral, a
second baseline: what an integral alone buys), runs
``rabbit_policy.evaluation.acceptance.broad_acceptance`` (every speed, every ordered change
at every phase, random command sequences, push margins against classic's and the paper's
scenarios beyond them, model errors and torque delays, Poincaré), prints one JSON line per
controller as it finishes (passed, failed checks) and then the markdown table (``broad_table``);
``--out`` gets every figure, rewritten after each controller (an interrupted run keeps what it
measured). ROS-free. Exit status 0 (whatever the verdicts), 2 for bad arguments or
a file that is not a policy.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser
from rabbit_policy.parallel import ProgressMap, add_backend_arguments, open_backend


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("policies", nargs="*", type=Path, help="learned policy checkpoints (.pt)")
    parser.add_argument("--classic-integral", nargs="+", type=float, default=[], metavar="KI",
                        help="also classic HZD with the event-based speed integral of this gain (1/s), one column each")
    parser.add_argument("--names", nargs="+", help="a column name per policy (default: the file paths)")
    parser.add_argument("--quick", action="store_true", help="the fast subset (RobustnessConfig.quick(), 30 "
                                                             "Poincaré samples): a first look only")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--out", type=Path, help="also write every figure to this JSON file")
    add_backend_arguments(parser)
    args = parser.parse_args(argv)
    if args.workers < 1:
        parser.error("--workers must be >= 1")
    if args.names is not None and len(args.names) != len(args.policies):
        parser.error(f"--names gives {len(args.names)} names for {len(args.policies)} policies")
    if not args.policies and not args.classic_integral:
        parser.error("give policy files, --classic-integral gains, or both")

    from rabbit_policy.evaluation.acceptance import broad_comparison, broad_table
    from rabbit_policy.runtime.policies import PolicyUnavailable, make_policy

    try:
        policies = [make_policy("learned", policy_file=p) for p in args.policies]
        policies += [make_policy("classic", speed_integral=ki) for ki in args.classic_integral]
    except (PolicyUnavailable, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    names = (args.names or [str(p) for p in args.policies]) + [f"classic + integral {ki:g}"
                                                              for ki in args.classic_integral]

    def log(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    backend = open_backend(parser, args)
    map_fn = ProgressMap(backend, "acceptance walks", enabled=not args.no_progress)
    broad: list[tuple[str, dict]] = []
    try:
        for name, result in broad_comparison(list(zip(names, policies)), args.quick, map_fn, log):
            broad.append(("classic HZD" if not broad else name, result))
            print(strict_json.dumps({"controller": broad[-1][0], "passed": result["passed"],
                                     "failed": result["failed"]}), flush=True)
            if args.out is not None:  # after each controller: an interrupted run keeps what it measured
                args.out.parent.mkdir(parents=True, exist_ok=True)
                args.out.write_text(strict_json.dumps({"quick": args.quick, "policies": [str(p) for p in args.policies],
                                                       "results": dict(broad)}, indent=1) + "\n")
    finally:
        map_fn.close()
        backend.close()
    print("\n".join(broad_table(broad)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
