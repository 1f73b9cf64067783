"""Run the RABBIT ROS 2 stack (simulator, HZD controller, policy) in place of a launch file.

    scripts/run_stack.py --speed 1.0 --duration 30
    scripts/run_stack.py --speed-schedule "0:0.8,10:1.2,20:1.0" --duration 30
    scripts/run_stack.py --speed 1.0 --duration 20 --push "5:60:0.1" --mode paced
    scripts/run_stack.py --speed 1.0 --duration 10 --in-process --json
    scripts/run_stack.py --speed 1.0 --duration 30 --record runs/walk1   # rosbag2 (MCAP) bag

By default (``--layout composed``) the simulator and the 1 kHz controller run in this
script's process beside its supervisor, on one executor, as a ROS component container runs
nodes (each still a node with its own name, parameters and topics), and the policy starts as
a process of its own (``python -m rabbit_policy.policy_node --ros-args -p ...``, as ``ros2
run`` would); ``--layout separate`` starts every node as its own process. This script
supervises the run: it sends
the speed schedule on ``/cmd_speed`` at its sim times (the pushes are sim_node's
``push_schedule``, applied at their exact sim times), and at the end prints, per schedule segment, the commanded speed and the mean hip speed over
the segment's second half, the steps, whether RABBIT fell, and the real-time factor
(sim time / wall time). ``--layout in-process`` (or ``--in-process``) runs every node in
this process on one EventsExecutor (the fastest; docs/benchmarks.md measures each layout).
Ctrl-C stops the nodes cleanly and prints what was measured so far. ``--attach`` starts no
node: it supervises a stack started by hand (``ros2 run``) in the namespace, sending the
schedule on ``/cmd_speed`` from the first state it sees (docs/ros2-cli.md).

With ``--json``: one object, the same keys as ``walk.py --json`` for the same scenario
(``rabbit_policy.experiment.result.run_summary``: ``fell``, ``steps``, ``segments`` with
``mean_speed`` and ``reach_time``, ``real_time_factor``, ``completed``, ``error``, ...);
node logs go to stderr.
Exit status: 0 walked the whole run and reached its last command, 1 fell or stalled (no touchdown
for 2 s), 2 bad arguments or another stack already running in this ROS_DOMAIN_ID (they would
cross-talk), 3 the run did not complete (a node died, no progress, interrupted, the policy
stopped deciding: ``decisions_lost`` > 0), 4 walked but never reached the last command
(``last_command_reached`` false).
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser, positive, unwritable_dir
from rabbit_msgs_py.environment import ensure_localhost_discovery


def build_parser() -> argparse.ArgumentParser:
    from rabbit_policy.bringup.config import LAYOUTS
    from rabbit_policy.experiment.options import add_model_options, add_policy_options, add_walk_options  # here: after main() took Ctrl-C over

    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_walk_options(parser)
    parser.add_argument("--mode", choices=("lockstep", "paced", "realtime"), default="lockstep",
                        help="lockstep: one torque per state, as fast as it goes (deterministic); paced: lockstep "
                             "held to the wall clock (--rtf), slower if the machine cannot keep up; realtime: "
                             "free-running 1 kHz wall clock (latency studies; halts if it falls behind)")
    parser.add_argument("--rtf", type=positive, default=1.0, help="--mode paced: target real-time factor (default 1)")
    add_model_options(parser)
    parser.add_argument("--namespace", default="", metavar="NS",
                        help="ROS namespace of every node and topic (e.g. rabbit2: /rabbit2/joint_states, ...); "
                             "stacks in different namespaces run side by side in one domain (default: the root)")
    add_policy_options(parser)
    parser.add_argument("--record", default="", metavar="DIR",
                        help="record every stack topic to a rosbag2 bag (MCAP) in DIR (must not exist)")
    parser.add_argument("--compression", "--record-compression", choices=("none", "zstd"), default="none",
                        help="--record: chunk compression (as record.py's)")
    parser.add_argument("--recorder-timeout", type=float, default=10.0, metavar="S",
                        help="--record: fail the run when the simulation waited this long (wall s) for a recorder "
                             "that has stopped writing (default 10; its first state may take up to 30 s)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --record DIR")
    parser.add_argument("--layout", choices=LAYOUTS, default="composed",
                        help="composed: simulator and controller in this process, the policy a process of its own "
                             "(default); separate: every node its own process; in-process: every node here")
    parser.add_argument("--in-process", dest="layout", action="store_const", const="in-process",
                        help="the same as --layout in-process")
    parser.add_argument("--attach", dest="layout", action="store_const", const="attach",
                        help="start no node: supervise the stack started by hand (ros2 run) in the namespace, send "
                             "the schedule on /cmd_speed from its newest state on, and report as for any run (the "
                             "same as --layout attach; pushes: sim_node's push_schedule)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--viewer", action="store_true", help="sim_node opens MuJoCo's viewer (needs a display)")
    parser.add_argument("--reference-rate", type=float, default=0.0, metavar="HZ",
                        help="the controller publishes /hzd/reference and /hzd/tracking_error this often per s of sim "
                             "time (0 = off), to plot when tuning Kp and Kd")
    parser.add_argument("--markers-rate", type=float, default=30.0, metavar="HZ",
                        help="/rabbit/markers (RViz/Foxglove 3D view) per s of sim time; 0 = off (default 30)")
    return parser


def print_report(report, config) -> None:
    print(f"controller   {report.controller}, {config.mode} mode, {'ok' if report.completed else 'incomplete'}"
          + (f" ({report.error})" if report.error else ""))
    print(f"fell         {report.fell}" + (f" at t = {report.fall_time:.3f} s" if report.fell else ""))
    if report.stalled:
        print(f"stalled      at t = {report.stall_time:.3f} s (no touchdown for {config.rules.stall_after} s)")
    print(f"steps        {report.steps}")
    print("segment         command   mean speed (2nd half)   reached in")
    for seg in report.segments:
        mean = "   n/a" if seg["mean_speed"] is None else f"{seg['mean_speed']:6.3f}"
        reach = "never" if seg["reach_time"] is None else f"{seg['reach_time']:.2f} s"
        print(f"{seg['start']:6.1f}-{seg['end']:6.1f} s  {seg['command']:5.2f}     {mean} m/s              {reach}")
    if report.decisions_lost:
        print(f"decisions    lost {report.decisions_lost} times: the policy stopped deciding (the controller's log "
              "says when)")
    if report.completed and not report.fell and not report.stalled and report.result.last_command_reached() is False:
        print("last command never reached")
    if report.sim_time > 0.0:
        print(f"simulated    {report.sim_time:.2f} s in {report.wall_time:.2f} s wall "
              f"(real-time factor {report.rtf:.2f})")
    else:
        print("simulated    nothing")


def main(argv: list[str] | None = None) -> int:
    ensure_localhost_discovery()
    # Ctrl-C / SIGTERM at any moment end the run cleanly: before the stack starts (the
    # imports, the checks, the probe for another stack) with exit 3 and an "interrupted"
    # report; during the run the loop sees the flag, stops the nodes and prints what was
    # measured so far
    interrupted: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: interrupted.append(signum))
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # bad arguments: with --json the report too (every exit prints one)
        if exc.code == 2 and "--json" in (sys.argv[1:] if argv is None else argv):
            from rabbit_policy.bringup.config import StackConfig
            from rabbit_policy.bringup.supervisor import RunReport

            unparsed = StackConfig(duration=parser.get_default("duration"), schedule=((0.0, parser.get_default("speed")),))
            print(strict_json.dumps({**RunReport.not_started(unparsed, "bad arguments (the error line says which)")
                                     .summary(), "spec": None}))
        raise

    from rabbit_policy.runtime.policies import PolicyUnavailable
    from rabbit_policy.experiment.options import resolve_controller
    from rabbit_policy.bringup.config import StackConfig
    from rabbit_sim.viewer import ViewerUnavailable
    from rabbit_policy.bringup.attached import NothingToAttach, run_attached
    from rabbit_policy.bringup.in_process import run_in_process
    from rabbit_policy.bringup.probe import AnotherStack, other_stack
    from rabbit_policy.bringup.processes import run_multi_process
    from rabbit_policy.bringup.supervisor import RunReport
    from rabbit_msgs_py.node_runner import NodeStartError

    def refused(error: str) -> None:
        """--json: the report of a run refused before it started (every exit prints one)."""
        if args.json:
            asked = config or StackConfig(duration=args.duration, schedule=((0.0, args.speed),),
                                          controller=args.controller or "classic")
            print(strict_json.dumps({**RunReport.not_started(asked, error).summary(), "spec": None}))

    config = None
    try:
        resolve_controller(args)
        config = _config_from(args)
        _check_outputs(args)
        built = config.build_policy() if config.layout != "attach" else None  # once: refused before any node starts
        policy = built.name if built is not None else None
    except ValueError as exc:
        refused(str(exc))
        parser.error(str(exc))
    except (PolicyUnavailable, ViewerUnavailable) as exc:  # (a --spec that is not one; --viewer without a display)
        print(f"error: {exc}", file=sys.stderr)
        refused(str(exc))
        return 2

    if interrupted:
        return _report_and_exit(RunReport.not_started(config, "interrupted"), config, args.json)
    stop = lambda: bool(interrupted)  # noqa: E731
    probe = lambda: other_stack(namespace=config.namespace, stop=stop)  # noqa: E731
    try:
        if config.layout == "attach":
            report, config = run_attached(config, stop=stop)
        elif config.layout == "in-process":
            found = probe()
            if found and not interrupted:
                raise AnotherStack(found)
            if interrupted:
                return _report_and_exit(RunReport.not_started(config, "interrupted"), config, args.json)
            report, _nodes = run_in_process(config, stop=stop, policy=built)
        else:  # the node processes import while the probe looks
            report = run_multi_process(config, log=sys.stderr if args.json else None, stop=stop, policy=policy,
                                       probe=probe)
    except AnotherStack as present:
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
        found = f"another rabbit-hzd stack runs in namespace {config.namespace or '/'} of ROS_DOMAIN_ID={domain} ({present})"
        print(f"error: {found}; stop it, or start this one in another namespace (--namespace rabbit2) or "
              f"domain (ROS_DOMAIN_ID={(int(domain) + 1) % 101 if domain.isdigit() else 1} scripts/run_stack.py ...)",
              file=sys.stderr)
        refused(found)
        return 2
    except NothingToAttach as exc:
        print(f"error: {exc}", file=sys.stderr)
        refused(str(exc))
        return 2
    except NodeStartError as exc:  # a node run in this process could not start: its one line, the report
        print(f"error: {exc}", file=sys.stderr)
        return _report_and_exit(RunReport.not_started(config, str(exc)), config, args.json)
    return _report_and_exit(report, config, args.json)


def _config_from(args):
    """The run's :class:`~rabbit_policy.bringup.config.StackConfig` from the parsed command line
    (the controller already resolved); ``ValueError`` saying which option is wrong."""
    from rabbit_policy.bringup.config import StackConfig
    from rabbit_policy.experiment.options import schedule_from_args
    from rabbit_policy.experiment.scenario import parse_pushes

    pushes = parse_pushes(args.push) if args.push else ()
    config = StackConfig(
        duration=args.duration, schedule=schedule_from_args(args), controller=args.controller, mode=args.mode,
        model=args.model, friction=args.friction or 0.0, torso_mass_scale=args.torso_mass_scale,
        torque_delay=args.torque_delay, library_mode=args.library_mode, gait_dir=args.gait_dir,
        policy_file=os.path.abspath(args.policy_file) if args.policy_file else "", pushes=pushes,
        decision=args.decision_period, speed_integral=args.speed_integral,
        record=os.path.abspath(args.record) if args.record else "",
        record_compression=args.compression, record_overwrite=args.overwrite,
        markers_rate=args.markers_rate, reference_rate=args.reference_rate, viewer=args.viewer, rtf=args.rtf,
        recorder_timeout=args.recorder_timeout, namespace=args.namespace, layout=args.layout,
    )
    if not (math.isfinite(args.markers_rate) and args.markers_rate >= 0.0):
        raise ValueError(f"--markers-rate must be a finite number >= 0, got {args.markers_rate}")
    if args.layout == "attach":
        given = [name for name, value in (("--record", args.record), ("--push", args.push),
                                          ("--viewer", args.viewer)) if value]
        if given:
            raise ValueError(f"--attach starts no node: {', '.join(given)} belong to the stack's own nodes "
                             "(recorder_node, sim_node's push_schedule and viewer parameters)")
    return config


def _check_outputs(args) -> None:
    """What the run needs outside itself: a display for ``--viewer``
    (:class:`~rabbit_sim.viewer.ViewerUnavailable`), a ``--record`` directory it may write
    (``ValueError``)."""
    if args.viewer:
        from rabbit_sim.viewer import require_display

        require_display()
    if args.record and os.path.exists(args.record):
        from rabbit_sim.bag import is_bag_directory

        if not args.overwrite:
            raise ValueError(f"--record {args.record} exists; choose another directory or pass --overwrite")
        if not is_bag_directory(Path(args.record)):
            raise ValueError(f"--record {args.record} is not a bag directory; refusing to overwrite it")
    problem = unwritable_dir(Path(os.path.abspath(args.record)).parent) if args.record else None
    if problem:
        raise ValueError(f"--record {args.record}: {problem}")


def _report_and_exit(report, config, as_json: bool) -> int:
    """Print the report (JSON or text); the exit status
    (:func:`~rabbit_policy.experiment.result.exit_status`): 1 fell or stalled, 3 not completed
    (interrupted, a node died, the policy stopped deciding), 4 never reached the last command,
    else 0."""
    from rabbit_policy.experiment.result import exit_status

    summary = report.summary()
    if as_json:
        from rabbit_policy.spec.make import spec_record

        known = report.controller == config.controller  # (attached: unknown when policy_node did not answer)
        print(strict_json.dumps({**summary, "spec": spec_record(config.controller, config.policy_file or None)
                                 if known else None}))
    else:
        print_report(report, config)
    return exit_status(summary)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    sys.exit(main())
