"""The broad evaluation of one or both controllers (``rabbit_policy.evaluation.robustness``):
every speed, every speed change at several phases, random command sequences, push margins
at every phase, model errors. ROS-free; prints one JSON object (``--out`` also writes it).

    scripts/robustness.py --controller classic learned --workers 2 --out runs/robustness.json
    scripts/robustness.py --controller learned --parts grid transitions --quick

``--library-mode`` picks the classic variant (nearest or interpolate); ``--policy-file`` the
learned one. Exit status 0, or 2 for bad arguments.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser, non_negative
from rabbit_msgs_py.environment import ensure_localhost_discovery
from rabbit_policy.experiment.options import add_policy_options
from rabbit_policy.parallel import ProgressMap, add_backend_arguments, open_backend
from rabbit_policy.runtime.policies import controller_argument

PARTS = ("grid", "transitions", "random", "pushes", "models")


def main(argv: list[str] | None = None) -> int:
    ensure_localhost_discovery()
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--controller", nargs="+", type=controller_argument, default=["classic"],
                        metavar="{classic,learned,recovery}")
    add_policy_options(parser)
    parser.add_argument("--max-command-step", type=non_negative, default=0.0,
                        help="command rate limit (m/s per step)")
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    add_backend_arguments(parser, progress=True)
    parser.add_argument("--quick", action="store_true", help="a small version (seconds)")
    parser.add_argument("--out", type=Path, default=None, help="also write the JSON here")
    args = parser.parse_args(argv)

    from rabbit_policy.evaluation import robustness as rb
    from rabbit_policy.runtime.policies import PolicyUnavailable, controller_name
    from rabbit_policy.spec.make import make_policy

    try:
        names = [controller_name(c) for c in args.controller]
        policies = {name: make_policy(name, args.gait_dir if name != "learned" else None,
                                      args.library_mode if name != "learned" else "interpolate",
                                      args.policy_file if name == "learned" else None, args.max_command_step,
                                      args.decision_period, args.speed_integral if name == "classic" else 0.0)
                    for name in names}
    except (PolicyUnavailable, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    config = rb.RobustnessConfig.quick() if args.quick else rb.RobustnessConfig()
    parts = {"grid": rb.speed_grid, "transitions": rb.transitions, "random": rb.random_sequences,
             "pushes": rb.push_margins, "models": rb.model_errors}
    start = time.perf_counter()
    results: dict = {"config": config.to_dict(), "controllers": {}}
    backend = open_backend(parser, args)
    map_fn = ProgressMap(backend, "robustness walks", enabled=not args.no_progress)
    try:
        for name, policy in policies.items():
            results["controllers"][name] = {"policy": policy.name}
            for part in args.parts:
                print(f"[{time.perf_counter() - start:7.1f} s] {name}: {part}", file=sys.stderr, flush=True)
                results["controllers"][name][part] = parts[part](policy, config, map_fn)
    finally:
        map_fn.close()
        backend.close()
    results["wall_time_s"] = round(time.perf_counter() - start, 1)
    text = strict_json.dumps(results)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
