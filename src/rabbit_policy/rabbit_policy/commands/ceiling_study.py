"""The ceiling of each action family for backward-push recovery (rabbit_policy.evaluation.ceiling):
an oracle that knows the push searches the actions after it with CMA-ES, on an impulse ladder of
multiples of classic HZD's margin, at every speed and phase asked for. Results go to a JSON-lines
file as they come (a rerun skips the cases already there), then a table per family and speed.

    python scripts/ceiling_study.py --out runs/ceiling.jsonl --workers 2
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from rabbit_msgs_py.cli import ArgumentParser
from rabbit_policy.evaluation.ceiling import FAMILIES, CeilingConfig, ceiling, ladder, summarize
from rabbit_policy.evaluation.robustness import phase_times
from rabbit_policy.parallel import add_backend_arguments, open_backend
from rabbit_policy.spec.make import make_policy


def _job(job: tuple) -> dict:
    speed, phase, push_time, family, impulses, config = job
    start = time.perf_counter()
    row = ceiling(speed, phase, push_time, FAMILIES[family], impulses, config)
    return {**row, "budget": config.budget, "seconds": round(time.perf_counter() - start, 1)}


def _pairs(text: str) -> dict[float, float]:
    try:
        return {float(k): float(v) for k, v in (item.split(":") for item in text.split(","))}
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected speed:margin,... got {text!r}") from None


def _floats(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers separated by commas, got {text!r}") from None


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, required=True, help="JSON-lines file (appended; cases in it are skipped)")
    parser.add_argument("--classic-margins", type=_pairs, default=_pairs("0.7:5,1.0:9,1.3:14"),
                        help="classic HZD's backward margin (N s) per speed: the ladder's unit "
                             "(default: docs/results, 2026-11-26)")
    parser.add_argument("--factors", type=_floats, default=(1.5, 2.0, 2.5, 3.0),
                        help="the ladder: these multiples of classic's margin")
    parser.add_argument("--phases", type=_floats, default=tuple(i / 8 for i in range(8)),
                        help="phases of the step the push lands at (the margin's eight by default)")
    parser.add_argument("--families", default=",".join(FAMILIES), help=f"some of {', '.join(FAMILIES)}")
    parser.add_argument("--budget", type=int, default=240, help="CMA-ES rollouts per impulse")
    parser.add_argument("--blocks", type=int, default=5, help="200 ms blocks of actions after the push")
    add_backend_arguments(parser)
    args = parser.parse_args(argv)
    families = [f for f in args.families.split(",") if f]
    unknown = [f for f in families if f not in FAMILIES]
    if unknown:
        parser.error(f"unknown families {unknown}; choose from {list(FAMILIES)}")
    try:
        config = CeilingConfig(budget=args.budget, blocks=args.blocks)
    except ValueError as exc:
        parser.error(str(exc))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    done = set()
    if args.out.exists():
        rows = [json.loads(line) for line in args.out.read_text().splitlines() if line.strip()]
        done = {(r["speed"], r["phase"], r["family"]) for r in rows}
    classic = make_policy("classic")
    jobs = []
    for speed, margin in args.classic_margins.items():
        times = phase_times(classic, speed, config.settle, args.phases)
        if times is None:
            parser.exit(2, f"error: classic HZD does not walk at {speed} m/s\n")
        for family in families:
            for phase, push_time in zip(args.phases, times):
                if (speed, phase, family) not in done:
                    jobs.append((speed, phase, push_time, family, ladder(margin, args.factors), config))
    print(f"{len(jobs)} cases to run ({len(done)} already in {args.out})", file=sys.stderr)
    backend = open_backend(parser, args)
    try:
        chunk = 2 * args.workers
        for i in range(0, len(jobs), chunk):
            rows = backend.map(_job, jobs[i:i + chunk])
            with args.out.open("a") as f:
                for row in rows:
                    f.write(json.dumps(row) + "\n")
            for row in rows:
                print(f"{row['family']:16s} {row['speed']:.1f} m/s phase {row['phase']:.3f}: "
                      f"{row['reached_Ns']:g} N s ({row['seconds']} s)", file=sys.stderr, flush=True)
    finally:
        backend.close()
    rows = [json.loads(line) for line in args.out.read_text().splitlines() if line.strip()]
    print(json.dumps({"config": vars(config), "table": summarize(rows)}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
