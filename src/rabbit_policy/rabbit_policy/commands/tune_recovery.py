"""Tune the recovery controller's constants on a push grid (rabbit_policy.gait_design.recovery_tuning):
CMA-ES over its four offsets and saturation, from the packaged constants; prints JSON (the best
constants, pushes survived, each generation's scores).

    python scripts/tune_recovery.py --workers 2 > runs/recovery_tuning.json
"""

from __future__ import annotations

import argparse
import json
import sys

from rabbit_msgs_py.cli import ArgumentParser
from rabbit_policy.gait_design.recovery_tuning import TuningConfig, tune
from rabbit_policy.parallel import add_backend_arguments, open_backend
from rabbit_policy.spec.make import make_policy


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--iterations", type=int, default=6, help="CMA-ES generations (as optimize_gaits.py)")
    parser.add_argument("--popsize", type=int, default=8)
    add_backend_arguments(parser)
    args = parser.parse_args(argv)
    if args.iterations < 1 or args.popsize < 2:
        parser.error("--iterations >= 1 and --popsize >= 2")
    config = TuningConfig(generations=args.iterations, popsize=args.popsize)
    backend = open_backend(parser, args)
    try:
        result = tune(make_policy("recovery"), config, backend.map, log=lambda m: print(m, file=sys.stderr, flush=True))
    finally:
        backend.close()
    print(json.dumps({"config": {k: v for k, v in vars(config).items()}, **result}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
