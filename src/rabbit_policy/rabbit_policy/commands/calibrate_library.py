"""Calibrate the gait library's interpolation (``interpolation.json`` beside the gaits).

    scripts/calibrate_library.py [--gait-dir DIR] [--weights 11] [--duration 20] [--workers 2]

Walks blends of each two neighbouring gaits at evenly spaced weights and writes the mean
speed each walked at (``rabbit_policy.gait_design.calibration``); ``GaitLibrary.interpolate``
then picks the blend measured to walk at the command. Run it after changing the gaits
(``scripts/optimize_gaits.py``). About 40 s on 2 cores for the 9-gait library.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser, positive
from rabbit_policy.parallel import add_backend_arguments, open_backend


def main(argv: list[str] | None = None) -> int:
    from rabbit_policy.experiment.options import add_gait_dir_option

    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_gait_dir_option(parser)
    parser.add_argument("--weights", type=int, default=11, help="blend weights per pair (>= 2)")
    parser.add_argument("--duration", type=positive, default=20.0, help="walk per blend, s of sim time")
    add_backend_arguments(parser)
    args = parser.parse_args(argv)
    from rabbit_policy.gait_design.calibration import CalibrationConfig, calibrate
    from rabbit_policy.runtime.gait_library import CALIBRATION_FILE, GaitLibrary, packaged_gait_dir

    directory = Path(args.gait_dir) if args.gait_dir else packaged_gait_dir()
    try:
        config = CalibrationConfig(args.weights, args.duration)
        library = GaitLibrary.load(directory)
    except (ValueError, FileNotFoundError) as exc:
        parser.error(str(exc))
    backend = open_backend(parser, args)
    try:
        calibration = calibrate(library, config, backend.map)
    finally:
        backend.close()
    (directory / CALIBRATION_FILE).write_text(strict_json.dumps(calibration.to_dict(), indent=1) + "\n")
    for speeds, rows in zip(zip(library.speeds, library.speeds[1:]), calibration.pairs):
        cells = " ".join("fail" if v is None else f"{v:.2f}" for _, v in rows)
        print(f"{speeds[0]:.2f}-{speeds[1]:.2f} m/s: {cells}")
    print(f"wrote {directory / CALIBRATION_FILE}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
