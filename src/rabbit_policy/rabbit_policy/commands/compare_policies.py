"""Checks 1-6 (the learning issue's broad acceptance) on several learned policies against one
classic reference, measured once: the ablation's table.

    scripts/compare_policies.py docs/learning/a_es_moderate/best.pt docs/learning/b_es_moderate/best.pt \\
        --names a b [--classic-integral 0.2] [--quick] [--workers 2] [--out runs/ablation_checks.json]

For classic HZD (the calibrated library, every 20 ticks), each policy file and each
``--classic-integral`` gain (classic HZD with Westervelt's event-based speed integral, a
second baseline: what an integral alone buys) and with ``--recovery`` the recovery controller
(the model-based push-recovery baseline), runs
``rabbit_policy.evaluation.acceptance.broad_acceptance`` (every speed, every ordered change
at every phase, random command sequences, push margins against classic's and the paper's
scenarios beyond them, model errors and torque delays, Poincaré), prints one JSON line per
controller as it finishes (passed, failed checks) and then the markdown table (``broad_table``);
``--out`` gets every figure, rewritten after each controller (an interrupted run keeps what it
measured). ``--recheck-stability`` measures check 6's Poincaré analysis again for every
controller of an earlier ``--out`` file of the same policies, names and gains, and judges
them again on the file's other figures (results from before the return map kept a policy's
memory with the cycle's state, 2026-11-25). ROS-free. Exit status 0 (whatever the verdicts),
2 for bad arguments, a file that is not a policy, or an ``--out`` file of other controllers.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser
from rabbit_policy.parallel import ProgressMap, add_backend_arguments, open_backend


def main(argv: list[str] | None = None) -> int:
    from rabbit_policy.experiment.options import add_classic_integral_option

    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("policies", nargs="*", type=Path, help="learned controllers: spec files (.yaml) or training checkpoints (.pt)")
    add_classic_integral_option(parser)
    parser.add_argument("--recovery", action="store_true",
                        help="also the recovery controller (the model-based push-recovery baseline), a column")
    parser.add_argument("--names", nargs="+", help="a column name per policy (default: the file paths)")
    parser.add_argument("--quick", action="store_true", help="the fast subset (RobustnessConfig.quick(), 30 "
                                                             "Poincaré samples): a first look only")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--out", type=Path, help="also write every figure to this JSON file")
    parser.add_argument("--recheck-stability", action="store_true",
                        help="only check 6's Poincaré analysis again, for every controller in --out (an earlier run "
                             "of these same arguments), judged again on the file's other figures")
    add_backend_arguments(parser)
    args = parser.parse_args(argv)
    if args.names is not None and len(args.names) != len(args.policies):
        parser.error(f"--names gives {len(args.names)} names for {len(args.policies)} policies")
    if not args.policies and not args.classic_integral and not args.recovery:
        parser.error("give policy files, --classic-integral gains or --recovery")

    from rabbit_policy.evaluation.acceptance import broad_comparison, broad_table
    from rabbit_policy.runtime.policies import PolicyUnavailable
    from rabbit_policy.spec.make import make_policy

    try:
        policies = [make_policy("learned", policy_file=p) for p in args.policies]
        policies += [make_policy("classic", speed_integral=ki) for ki in args.classic_integral]
        policies += [make_policy("recovery")] if args.recovery else []
    except (PolicyUnavailable, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    names = (args.names or [str(p) for p in args.policies]) + [f"classic + integral {ki:g}"
                                                              for ki in args.classic_integral]
    names += ["recovery"] if args.recovery else []

    def log(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    stored = None
    if args.recheck_stability:
        try:
            stored = _stored_run(args, names)
        except (OSError, ValueError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    backend = open_backend(parser, args)
    map_fn = ProgressMap(backend, "acceptance walks", enabled=not args.no_progress)
    broad: list[tuple[str, dict]] = []
    try:
        if stored is not None:
            results = _recheck(stored, [make_policy("classic")] + policies, args.quick, map_fn, log)
        else:
            results = broad_comparison(list(zip(names, policies)), args.quick, map_fn, log)
        for name, result in results:
            broad.append(("classic HZD" if not broad else name, result))
            print(strict_json.dumps({"controller": broad[-1][0], "passed": result["passed"],
                                     "failed": result["failed"]}), flush=True)
            if args.out is not None:  # after each controller: an interrupted run keeps what it measured
                args.out.parent.mkdir(parents=True, exist_ok=True)
                results_so_far = {**(stored or {}).get("results", {}), **dict(broad)}  # a re-check keeps the rest
                args.out.write_text(strict_json.dumps({"quick": args.quick, "policies": [str(p) for p in args.policies],
                                                       "results": results_so_far}, indent=1) + "\n")
    finally:
        map_fn.close()
        backend.close()
    print("\n".join(broad_table(broad)))
    return 0


def _stored_run(args: argparse.Namespace, names: list[str]) -> dict:
    """The ``--out`` file to re-check, or ``ValueError`` if it is not a run of these arguments."""
    if args.out is None:
        raise ValueError("--recheck-stability needs --out: the earlier run's JSON file")
    stored = json.loads(args.out.read_text())
    expected = ["classic HZD"] + names
    if stored.get("policies") != [str(p) for p in args.policies] or list(stored.get("results", {})) != expected:
        raise ValueError(f"{args.out} holds {list(stored.get('results', {}))} of {stored.get('policies')}; these "
                         f"arguments name {expected} of {[str(p) for p in args.policies]}")
    if stored.get("quick") != args.quick:
        raise ValueError(f"{args.out} was measured with quick={stored.get('quick')}, not {args.quick}")
    from rabbit_policy.evaluation.robustness import RobustnessConfig

    config = json.loads(strict_json.dumps((RobustnessConfig.quick() if args.quick else RobustnessConfig()).to_dict()))
    for name, result in stored["results"].items():
        if result.get("config") != config:
            raise ValueError(f"{args.out}: {name} was measured with another RobustnessConfig than today's")
    return stored


def _recheck(stored: dict, policies: list, quick: bool, map_fn, log):
    """``(name, result)`` per controller of ``stored`` with check 6 measured again."""
    from rabbit_policy.evaluation.acceptance import rejudge_stability
    from rabbit_policy.evaluation.robustness import RobustnessConfig

    config = RobustnessConfig.quick() if quick else RobustnessConfig()
    for (name, result), policy in zip(stored["results"].items(), policies):
        log(f"{name}: Poincaré analysis again")
        yield name, rejudge_stability(result, policy, 30 if quick else 400, config, map_fn)


if __name__ == "__main__":
    sys.exit(main())
