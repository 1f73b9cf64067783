#!/usr/bin/env python3
"""Walk RABBIT in MuJoCo without ROS and print a summary.

    scripts/walk.py --controller hzd --speed 1.0 --duration 60 [--json]
    scripts/walk.py --controller rl  --speed 1.2 --duration 30 --json
    scripts/walk.py --controller rl  --schedule "0:0.8,10:1.2,20:0.9,30:1.5,40:0.7" --duration 50

``--controller hzd`` is classic HZD: at a constant speed the packaged library gait whose
design speed is nearest to ``--speed``, started on that gait; with a ``--schedule`` the
library gait for the commanded speed is chosen at every step (``--library-mode``).
``--controller rl`` is HZD-RL: the learned policy (default: the one shipped with
``rabbit_policy``, or ``--policy-file``) picks alpha and Kd at every touchdown from the
commanded speed and the last step's mean hip speed and error, exactly as ``policy_node``.

Prints whether it fell, steps, mean forward speed over the last half, and for a schedule
each segment's time to reach its speed (first step average within ``--tolerance``) and
its mean speed over the segment's second half.
Exit status: 0 walked, 1 fell, 2 bad arguments or no policy.
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
    parser.add_argument("--schedule", default=None, help='speed schedule "t:v,t:v,..." (s:m/s), first at 0')
    parser.add_argument("--duration", type=float, default=20.0, help="simulated time (s)")
    parser.add_argument("--model", choices=("paper", "drives"), default="paper", help="model variant")
    parser.add_argument("--gait-dir", default=None, help="gait library directory (default: packaged)")
    parser.add_argument("--library-mode", choices=("nearest", "interpolate"), default="nearest",
                        help="classic HZD with a schedule: nearest gait or blend")
    parser.add_argument("--policy-file", default=None, help="learned policy checkpoint (default: packaged)")
    parser.add_argument("--tolerance", type=float, default=0.05, help="reached = within this (m/s)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if not args.duration > 0:
        parser.error("--duration must be > 0")

    from rabbit_policy.evaluation.acceptance import segment_summaries
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.policies import PolicyUnavailable, make_policy
    from rabbit_policy.experiment.walk import walk_policy
    from rabbit_policy.experiment.scenario import parse_schedule
    from rabbit_policy.experiment.setup import walk_gait

    try:
        schedule = parse_schedule(args.schedule) if args.schedule else ((0.0, args.speed),)
    except ValueError as exc:
        parser.error(str(exc))
    start = time.perf_counter()
    if args.controller == "hzd" and args.schedule is None:
        gait = GaitLibrary.load(args.gait_dir).nearest(args.speed)
        result = walk_gait(gait, args.duration, args.model)
        summary = {"controller": "hzd", "policy": f"library gait {gait.speed:.2f} m/s", "gait_speed": gait.speed,
                   **result.summary()}
        fell = result.fell
    else:
        try:
            policy = make_policy("learned" if args.controller == "rl" else "library", args.gait_dir,
                                 args.library_mode, args.policy_file)
        except (PolicyUnavailable, ValueError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        start = time.perf_counter()  # the walk, not loading torch and the policy
        walk = walk_policy(policy, schedule, args.duration, model_variant=args.model)
        fell = walk.fell
        half = 0.5 * args.duration
        summary = {"controller": args.controller, "policy": policy.name, "fell": walk.fell,
                   "fall_time": walk.fall_time, "duration": walk.duration, "steps": len(walk.steps),
                   "mean_speed": None if walk.fell else walk.mean_speed(half), "rejected": walk.rejected}
        if args.schedule:
            summary["segments"] = segment_summaries(walk, schedule, args.duration, args.tolerance)
    wall = time.perf_counter() - start
    summary = {"model": args.model, "commanded_speed": None if args.schedule else args.speed,
               **summary, "real_time_factor": summary["duration"] / wall if wall > 0 else None}
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"controller      {summary['controller']} ({summary['policy']})")
        print(f"fell            {fell}" + (f" at t = {summary['fall_time']:.3f} s" if fell else ""))
        print(f"steps           {summary['steps']}")
        if summary["mean_speed"] is not None:
            print(f"mean speed      {summary['mean_speed']:.3f} m/s (last half)")
        for key in ("step_length", "step_period", "peak_torque"):
            if key in summary:
                print(f"{key.replace('_', ' '):15s} {summary[key]:.3f}")
        for seg in summary.get("segments", []):
            reach = "not reached" if seg["reach_time"] is None else f"reached in {seg['reach_time']:.2f} s"
            mean = seg["mean_speed_second_half"]
            print(f"  from {seg['start']:5.1f} s  {seg['speed']:.2f} m/s  {reach}, second-half mean "
                  + ("—" if mean is None else f"{mean:.3f} m/s"))
        print(f"simulated       {summary['duration']:.1f} s in {wall:.1f} s wall "
              f"({summary['real_time_factor']:.0f}x real time)")
    return 1 if fell else 0


if __name__ == "__main__":
    sys.exit(main())
