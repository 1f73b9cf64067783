#!/usr/bin/env python3
"""Walk RABBIT in MuJoCo without ROS and print a summary.

    scripts/walk.py --controller hzd --speed 1.0 --duration 60 [--json]

``--controller hzd`` runs the classic HZD gait from the packaged library whose design
speed is nearest to ``--speed``. Prints whether it fell, steps taken, mean forward speed
over the last half, step length and period, and the peak joint torque.
Exit status: 0 walked, 1 fell, 2 bad arguments.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from rabbit_msgs_py.environment import ensure_localhost_discovery


def main(argv: list[str] | None = None) -> int:
    ensure_localhost_discovery()
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--controller", choices=("hzd", "rl"), default="hzd")
    parser.add_argument("--speed", type=float, default=1.0, help="desired speed (m/s)")
    parser.add_argument("--duration", type=float, default=20.0, help="simulated time (s)")
    parser.add_argument("--model", choices=("paper", "drives"), default="paper", help="model variant")
    parser.add_argument("--gait-dir", default=None, help="gait library directory (default: packaged)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if not args.duration > 0:
        parser.error("--duration must be > 0")

    from rabbit_policy.gait_library import GaitLibrary
    from rabbit_policy.walking import walk_gait

    if args.controller == "rl":
        print("error: no learned HZD-RL policy is shipped yet; use --controller hzd", file=sys.stderr)
        return 2
    gait = GaitLibrary.load(args.gait_dir).nearest(args.speed)
    start = time.perf_counter()
    result = walk_gait(gait, args.duration, args.model)
    wall = time.perf_counter() - start
    summary = {
        "controller": args.controller,
        "model": args.model,
        "commanded_speed": args.speed,
        "gait_speed": gait.speed,
        **result.summary(),
        "real_time_factor": result.duration / wall if wall > 0 else None,
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"controller      {args.controller} (classic gait designed for {gait.speed:.2f} m/s)")
        print(f"fell            {result.fell}" + (f" at t = {result.fall_time:.3f} s" if result.fell else ""))
        print(f"steps           {result.steps}")
        print(f"mean speed      {result.mean_speed:.3f} m/s (last half, commanded {args.speed:.2f})")
        print(f"step length     {result.step_length:.3f} m")
        print(f"step period     {result.step_period:.3f} s")
        print(f"peak torque     {result.peak_torque:.1f} N m")
        rtf = summary["real_time_factor"]
        print(f"simulated       {result.duration:.1f} s in {wall:.1f} s wall ({rtf:.0f}x real time)")
    return 1 if result.fell else 0


if __name__ == "__main__":
    sys.exit(main())
