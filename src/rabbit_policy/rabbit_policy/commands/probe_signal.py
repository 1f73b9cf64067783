"""Measure the training signal of a preset before spending a seed on it; prints one JSON object.

    scripts/probe_signal.py --preset shipped --sigmas 0.02,0.2 [--pairs 16] [--episodes 8]

The preset's start (``start: zero``: the packaged learned spec with its network restarted from
the preset's first seed; or the spec it names) and its episodes (distribution, fall penalty,
length); each of ``--sigmas`` (default: the preset's sigma) is probed with fresh draws of ``--seed``
(:mod:`rabbit_policy.learning.signal`: the correlation of the mirrored differences on two
independent episode sets, and the cosines between gradient estimates). A preset is worth its
budget when ``difference_correlation`` is at least 0.5 (docs/learning.md).
"""

from __future__ import annotations

import sys
import tempfile
from dataclasses import fields
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser
from rabbit_msgs_py.environment import ensure_localhost_discovery


def sigma_list(text: str) -> list[float]:
    """``"0.02,0.2"`` -> [0.02, 0.2]: each a finite number > 0 (argparse's type)."""
    import argparse
    import math

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"a comma-separated list of numbers > 0, got {text!r}") from None
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"a comma-separated list of numbers > 0, got {text!r}")
    return values


def main(argv: list[str] | None = None) -> int:
    from rabbit_policy.parallel import add_backend_arguments, open_backend

    ensure_localhost_discovery()
    parser = ArgumentParser(description=__doc__)
    parser.add_argument("--preset", default="shipped", help="config/reproduce/NAME.yaml or a .yaml file (default shipped)")
    parser.add_argument("--sigmas", type=sigma_list, default=None, metavar="S,S,...",
                        help="the perturbation stds to probe, parameter units (default the preset's sigma)")
    parser.add_argument("--pairs", type=int, default=16, help="directions, >= 2 (default 16)")
    parser.add_argument("--episodes", type=int, default=0, help="episodes per set, >= 1 (default the preset's)")
    parser.add_argument("--seed", type=int, default=0, help="the probe's draws (default 0)")
    parser.add_argument("--out", type=Path, default=None, help="also write the JSON to this file")
    add_backend_arguments(parser, workers=True)
    args = parser.parse_args(argv)
    if args.pairs < 2 or args.episodes < 0:
        parser.error("--pairs must be >= 2 and --episodes >= 1")
    from rabbit_policy.commands.reproduce import load_preset, preset_dir, write_start

    try:
        preset = load_preset(args.preset)
    except ValueError as exc:
        parser.error(str(exc))
    if args.out is not None and not (args.out.parent.is_dir() and not args.out.is_dir()):
        parser.error(f"--out {args.out}: not a file in an existing directory")

    import numpy as np

    from rabbit_policy.learning.es import ESConfig, get_flat
    from rabbit_policy.learning.signal import probe
    from rabbit_policy.runtime.network import spec_network
    from rabbit_policy.spec import load_controller

    train = preset["train"]
    names = {f.name for f in fields(ESConfig)} - {"workers", "seed"}
    results = []
    with tempfile.TemporaryDirectory(prefix="rabbit_probe_") as scratch:
        start = write_start(preset["start"], preset["seeds"][0], Path(scratch) / "start.yaml")
        config = ESConfig(**{k: v for k, v in train.items() if k in names}, spec=str(start))
        key = tuple(sorted(config.env_kwargs().items()))
        theta = get_flat(spec_network(load_controller(start).forward))
        backend = open_backend(parser, args)
        try:
            for sigma in args.sigmas or [config.sigma]:
                row = probe(backend.map, key, np.asarray(theta), sigma, args.pairs, args.episodes or config.episodes,
                            args.seed)
                print(f"sigma {sigma:g}: difference correlation {row['difference_correlation']:+.2f} (chance "
                      f"+-{row['chance_level']:.2f}), gradient cosines {row['cosine_same_directions']:+.2f} (same "
                      f"directions) {row['cosine_fresh_directions']:+.2f} (fresh)", file=sys.stderr, flush=True)
                results.append(row)
        finally:
            backend.close()
    root, path = preset_dir().parents[1], Path(preset["path"]).resolve()  # the repository's path, not this machine's
    report = {"preset": str(path.relative_to(root) if path.is_relative_to(root) else path), "start": preset["start"],
              "distribution": config.distribution, "reward": config.reward, "fall_penalty": config.fall_penalty,
              "max_steps": config.max_steps, "probes": results}
    text = strict_json.dumps(report)
    if args.out is not None:
        args.out.write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
