"""Draw the ``/rabbit/markers`` of a recorded bag side-on (what RViz/Foxglove show) to a PNG,
without a GUI.

    scripts/render_markers.py runs/walk1 --time 5.0 --out walk1_t5.png
    scripts/render_markers.py runs/walk1 --times 4.0,4.2,4.4 --out strip.png   # several, side by side

``--time``: the first marker message whose stamp (sim time, s) is at or after it (default:
the first). Exit status: 0 written, 2 bad arguments, no bag or no markers in it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rabbit_msgs_py.cli import ArgumentParser


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("bag", help="rosbag2 bag directory")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--time", type=float, default=0.0, help="sim time of the frame (s)")
    group.add_argument("--times", default=None, help="comma-separated sim times: one panel each")
    parser.add_argument("--out", type=Path, required=True, help="PNG to write")
    args = parser.parse_args(argv)
    try:
        times = [float(t) for t in args.times.split(",")] if args.times else [args.time]
    except ValueError:
        parser.error(f"--times: numbers separated by commas, got {args.times!r}")

    from rabbit_sim.bag import BagError
    from rabbit_sim.marker_plot import marker_frames, render_strip

    try:
        frames = marker_frames(Path(args.bag), times)
    except (BagError, OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    render_strip(frames, args.out)
    print(f"wrote {args.out} ({len(frames)} frame{'s' if len(frames) > 1 else ''})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
