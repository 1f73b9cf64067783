"""Choose among a training run's policies on held-out checks (``rabbit_policy.evaluation.selection``):
the ordered speed changes at other phases, random command sequences from other seeds and the
judged model errors at other speeds than checks 1-6 use, so that the policy chosen can then be
judged on checks 1-6 (``scripts/compare_policies.py``) without having been chosen on them.

    scripts/screen_policies.py runs/final_gated_es/evaluated/*.pt [--classic-integral 0.2] [--classic] \\
        [--workers 2] [--out runs/screen.jsonl] [--quick]

Train with ``train.py --keep-evaluated`` to keep every evaluated policy. Prints one JSON line
per controller as it finishes (also appended to ``--out``), then the controllers best first
(fewest failures, then fewest falls and stalls). ROS-free. Exit status 0, 2 for bad arguments
or a file that is not a policy.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser
from rabbit_policy.parallel import ProgressMap, add_backend_arguments, open_backend


def main(argv: list[str] | None = None) -> int:
    from rabbit_policy.experiment.options import add_classic_integral_option

    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("policies", nargs="*", type=Path, help="learned controllers: spec files (.yaml) or training checkpoints (.pt)")
    parser.add_argument("--classic", action="store_true", help="also classic HZD (the calibrated library)")
    add_classic_integral_option(parser)
    parser.add_argument("--quick", action="store_true", help="a few walks per controller (a smoke test)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--out", type=Path, help="also append each controller's JSON line to this file")
    add_backend_arguments(parser)
    args = parser.parse_args(argv)
    if not (args.policies or args.classic or args.classic_integral):
        parser.error("give policy files, --classic, --classic-integral gains, or several")

    from rabbit_policy.evaluation.selection import HELD_OUT, quick_screen_config, screen, screen_rank
    from rabbit_policy.runtime.policies import PolicyUnavailable
    from rabbit_policy.spec.make import make_policy

    try:
        named = [(str(p), make_policy("learned", policy_file=p)) for p in args.policies]
        named += [("classic HZD", make_policy("classic"))] if args.classic else []
        named += [(f"classic + integral {ki:g}", make_policy("classic", speed_integral=ki))
                  for ki in args.classic_integral]
    except (PolicyUnavailable, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    config = quick_screen_config() if args.quick else HELD_OUT
    backend = open_backend(parser, args)
    map_fn = ProgressMap(backend, "screen walks", enabled=not args.no_progress)
    results = []
    try:
        for name, policy in named:
            result = {"controller": name, **screen(policy, config, map_fn)}
            results.append(result)
            line = strict_json.dumps(result)
            print(line, flush=True)
            if args.out is not None:
                args.out.parent.mkdir(parents=True, exist_ok=True)
                with args.out.open("a") as out:
                    out.write(line + "\n")
    finally:
        map_fn.close()
        backend.close()
    print("best first (failures, falls and stalls):")
    for result in sorted(results, key=screen_rank):
        print(f"  {result['failures']:4d} {result['falls']:4d}  changes {result['changes']}, random "
              f"{result['random']}, models {result['models']}  {result['controller']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
