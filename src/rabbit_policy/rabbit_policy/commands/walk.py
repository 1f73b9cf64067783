"""Walk RABBIT in MuJoCo without ROS: the one experiment command.

    scripts/walk.py --controller classic --speed 1.0 --duration 60
    scripts/walk.py --controller learned --speed-schedule "0:0.8,10:1.2,20:0.9" --duration 30 --json
    scripts/walk.py --controller learned --speed 1.0 --push "3:-100:0.1" --friction 0.4 --json
    scripts/walk.py --controller classic --speed 1.2 --model drives --torque-delay 0.005
    scripts/walk.py --controller recovery --speed 1.0 --push "3.875:-180:0.1" --duration 8 --video walk.gif

``--controller classic`` is classic HZD (the packaged gait library: the calibrated blend
that walks at the command, or ``--library-mode nearest``); ``--controller learned`` is
HZD-RL (the shipped policy or ``--policy-file``); ``--controller recovery`` is classic plus
the model-based push-recovery rule (``rabbit_policy.runtime.recovery``). Each picks alpha
and Kd as ``policy_node`` does (classic and recovery every 20 ticks, learned as trained;
``--decision-period`` overrides), on the closed loop every experiment runs
(``rabbit_policy.experiment.loop``). ``hzd`` and ``rl`` are accepted as aliases.

The robot starts on the gait for the first commanded speed, moving at it. Pushes are
``T:FX:DUR`` (sim time s, force N along world x on the torso, duration s). Model errors:
``--model drives`` (the real robot's gears and joint friction), ``--friction`` (foot
friction coefficient, 0.8 by default), ``--torso-mass-scale``, ``--torque-delay`` (s).
``--video FILE.gif``: the walk as an animated GIF (offscreen, 25 frames per s of sim time,
320 x 240; on a machine without a display MuJoCo's EGL or OSMesa backend is chosen by itself).

``--json`` prints one object, always with the same keys: ``fell``, ``stalled``,
``fall_time``, ``stall_time``, ``duration``, ``steps``, ``mean_speed`` (m/s, last half;
null after a fall or stall), ``peak_torque`` (N m), ``rejected``, ``touchdowns`` (sim
times, s), ``segments`` (``command``, ``start``, ``end``, ``mean_speed`` over the
segment's second half, ``reach_time``: s from the change to the end of the first whole
step within ``--tolerance`` of the command, or null), plus ``controller``, ``policy``,
``scenario``, ``real_time_factor``, ``wall_time`` (s), ``completed``, ``error`` and ``spec``
(``file``, ``sha256``: the spec or checkpoint the controller was built from). No NaN: null
instead. ``--spec FILE``: a controller spec of any kind, run as the kind its file says.
``last_command_reached``: the last segment's command was reached. Exit status: 0 walked and
reached the last command, 1 fell or stalled, 2 bad arguments or no policy, 4 walked but never
reached the last command (``rabbit_policy.experiment.result.exit_status``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser, non_negative, positive
from rabbit_msgs_py.environment import ensure_localhost_discovery


def build_parser() -> argparse.ArgumentParser:
    from rabbit_policy.experiment.options import add_model_options, add_policy_options, add_walk_options  # here: after main() took Ctrl-C over

    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_walk_options(parser)
    add_model_options(parser)
    add_policy_options(parser)
    parser.add_argument("--max-command-step", type=non_negative, default=0.0,
                        help="command rate limit (m/s per step; 0: none, the default)")
    parser.add_argument("--video", default=None, metavar="FILE.gif",
                        help="also write the walk as an animated GIF, rendered offscreen from the recorded motion "
                             "(25 frames per s of sim time, 320 x 240; MUJOCO_GL=egl or osmesa, chosen by itself "
                             "on a machine without a display)")
    parser.add_argument("--tolerance", type=positive, default=0.05, help="reached = a step within this (m/s)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--viewer", action="store_true",
                        help="watch the walk in MuJoCo's viewer, at real time (needs a display; results unchanged)")
    return parser


def print_summary(summary: dict) -> None:
    print(f"controller      {summary['controller']} ({summary['policy']})")
    ended = "fell" if summary["fell"] else "stalled" if summary["stalled"] else None
    when = summary["fall_time"] if summary["fell"] else summary["stall_time"]
    print(f"outcome         {ended} at t = {when:.3f} s" if ended else "outcome         walked")
    print(f"steps           {summary['steps']}")
    if summary["mean_speed"] is not None:
        print(f"mean speed      {summary['mean_speed']:.3f} m/s (last half)")
    print(f"peak torque     {summary['peak_torque']:.1f} N m")
    for seg in summary["segments"]:
        reach = "not reached" if seg["reach_time"] is None else f"reached in {seg['reach_time']:.2f} s"
        mean = "—" if seg["mean_speed"] is None else f"{seg['mean_speed']:.3f} m/s"
        print(f"  {seg['start']:6.1f}-{seg['end']:6.1f} s  {seg['command']:.2f} m/s  {reach}, second-half mean {mean}")
    rtf = summary["real_time_factor"]
    print(f"simulated       {summary['duration']:.1f} s" + (f" ({rtf:.0f}x real time)" if rtf else ""))


VIDEO_FPS = 25.0  # frames per s of sim time


def write_video(result, scenario, path: Path) -> str:
    """The walk as an animated GIF at ``path`` (its fall held 1.5 s); an error line, or ''."""
    from rabbit_sim.physics.model import load_model
    from rabbit_sim.rendering import RenderingUnavailable, caption_frames, frame_indices, render_frames, save_gif

    shown = frame_indices(result.times, VIDEO_FPS)
    try:
        frames = caption_frames(render_frames(load_model(scenario.model), result.qpos[shown]), result.times[shown],
                                scenario.pushes)
    except RenderingUnavailable as exc:
        return f"--video: {exc}"
    save_gif(frames, path, VIDEO_FPS, hold_last=1.5 if result.failed else 0.0)
    print(f"video: {path} ({len(frames)} frames)", file=sys.stderr)
    return ""


def main(argv: list[str] | None = None) -> int:
    ensure_localhost_discovery()
    given = sys.argv[1:] if argv is None else argv
    if not os.environ.get("DISPLAY") and any(a == "--video" or a.startswith("--video=") for a in given):
        from rabbit_msgs_py.gl_backend import choose_headless_gl

        choose_headless_gl()  # offscreen rendering: before anything imports mujoco (build_parser does)
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.video is not None:
        video = Path(args.video)
        if video.suffix.lower() != ".gif":
            parser.error(f"--video writes an animated GIF: give a FILE.gif, got {args.video}")
        if not video.resolve().parent.is_dir():
            parser.error(f"--video {args.video}: its directory does not exist")

    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.experiment.result import exit_status, run_summary
    from rabbit_policy.experiment.scenario import Scenario, parse_pushes
    from rabbit_policy.experiment.options import model_options, resolve_controller, schedule_from_args
    from rabbit_policy.runtime.policies import PolicyUnavailable
    from rabbit_policy.spec.make import make_policy, spec_record

    try:
        resolve_controller(args)
    except (PolicyUnavailable, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        schedule = schedule_from_args(args)
        scenario = Scenario(schedule=schedule, pushes=parse_pushes(args.push), torque_delay=args.torque_delay,
                            model=model_options(args))
    except ValueError as exc:
        parser.error(str(exc))
    controller = args.controller
    try:
        policy = make_policy(controller, args.gait_dir or None, args.library_mode, args.policy_file or None,
                             args.max_command_step, args.decision_period, args.speed_integral)
    except (PolicyUnavailable, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    viewer = None
    if args.viewer:
        from rabbit_sim.viewer import ViewerObserver, ViewerUnavailable

        try:
            viewer = ViewerObserver(realtime=True)
        except ViewerUnavailable as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    start = time.perf_counter()  # the walk, not loading torch and the policy
    try:
        result = walk(policy, scenario, args.duration, observer=viewer, record_state=args.video is not None)
    except Exception as exc:  # noqa: BLE001 - the viewer's window failed to open on the first tick
        if viewer is None or type(exc).__name__ != "ViewerUnavailable":
            raise
        print(f"error: {exc}", file=sys.stderr)
        return 2
    finally:
        if viewer is not None:
            viewer.close()
    wall = time.perf_counter() - start
    if args.video is not None:
        error = write_video(result, scenario, Path(args.video))
        if error:
            print(f"error: {error}", file=sys.stderr)
            return 2
    summary = {**run_summary(controller, policy.name, result, wall, tolerance=args.tolerance),
               "spec": spec_record(controller, args.policy_file or None)}
    if args.json:
        print(strict_json.dumps(summary))
    else:
        print_summary(summary)
    return exit_status(summary)


if __name__ == "__main__":
    sys.exit(main())
