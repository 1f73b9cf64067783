"""Soak benchmark: the ROS 2 stack for an hour of sim time (or ``--duration``) in lockstep, with
a random command every 5-20 s and small pushes; prints one JSON object.

    scripts/bench_soak.py --layout composed --controller learned [--duration 3600] [--record DIR]

It runs ``run_stack.py --json`` (``--layout`` composed, separate or in-process) as a
process; ``--layout hand`` starts the three nodes as ``ros2 run`` would (``python -m <node>
--ros-args -p ...``, the user's pairing key; the simulator paused, with the pushes as its
``push_schedule`` and the hour as its ``stop_time``; the controller's ``stats_file``) and
watches them with ``run_stack.py --attach --json``, which sends the commands; at the end it
stops the nodes as Ctrl-C would and adds the controller's own count of lost decisions. Beside
it, in this process, an observer node on ``/clock`` and a sampler of the
stack's processes (``/proc``: resident memory and CPU time of run_stack and its children,
every 2 s of wall time, with the sim time then). What it reports:

* ``decisions_lost`` (the controller's count of times the policy did not decide: 0 when
  every due decision was made), ``completed``, ``fell``, ``stalled``, ``real_time_factor``;
* ``commands``, ``commands_reached`` and ``unreached`` (each segment whose command no whole
  step came within 0.05 m/s of, with its start: reported, not hidden);
* ``clock_fraction_by_tenth``: ``/clock`` messages received in each tenth of the run over
  those due (``clock_rate`` 100 Hz of sim time), and its minimum;
* ``rss_mb_first_tenth`` / ``rss_mb_last_tenth`` (the stack's processes together, the mean
  of the samples in each tenth) and ``cpu_us_per_tick_first_tenth`` / ``_last_tenth``;
* with ``--record DIR``: ``recorded_states`` and ``states_lost`` (ticks simulated minus
  distinct ``/joint_states`` stamps in the bag; 0 by design).

The scenario is drawn from ``--seed`` (commands uniform in 0.7-1.5 m/s, at most 0.3 m/s from the
one before; a push of
``--push-impulse`` N s over 0.1 s, backward or forward, every 20-40 s), the same on every
machine. Results: docs/benchmarks.md ("Soak").

Killed outright (SIGTERM, SIGKILL), it takes its run_stack with it: the child gets SIGINT and stops
its nodes in order, as on Ctrl-C.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser, positive, unwritable_dir
from rabbit_msgs_py.environment import ensure_localhost_discovery
from rabbit_policy.bringup.processes import controller_counts
from rabbit_policy.runtime.policies import controller_argument

CLOCK_RATE = 100.0
"""Hz of sim time: sim_node's default ``clock_rate``."""
MAX_CHANGE = 0.3
"""m/s: the largest change between two commands of the soak (it measures time, not agility:
larger random jumps make a fall within the hour likely; docs/results.md rates those)."""
SAMPLE_EVERY = 2.0
"""s (wall) between two samples of the stack's processes."""


def soak_scenario(seed: int, duration: float, impulse: float) -> tuple[str, str]:
    """(speed schedule, pushes) as run_stack's options: every 5-20 s a command uniform in 0.7-1.5
    m/s within :data:`MAX_CHANGE` of the one before; a push of ``impulse`` N s over 0.1 s, either way, every 20-40 s."""
    rng = random.Random(seed)
    schedule, t = [(0.0, 1.0)], 0.0
    while True:
        t = round(t + rng.uniform(5.0, 20.0), 3)
        if t > duration - 5.0:
            break
        last = schedule[-1][1]
        schedule.append((t, round(rng.uniform(max(0.7, last - MAX_CHANGE), min(1.5, last + MAX_CHANGE)), 3)))
    pushes, t = [], 0.0
    while True:
        t = round(t + rng.uniform(20.0, 40.0), 3)
        if t > duration - 5.0:
            break
        pushes.append((t, rng.choice((-1.0, 1.0)) * impulse / 0.1, 0.1))
    return (",".join(f"{a}:{b}" for a, b in schedule), ",".join(f"{a}:{f:g}:{d}" for a, f, d in pushes))


def process_tree(root: int) -> list[int]:
    """``root`` and every process descended from it (Linux ``/proc``)."""
    parents: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            parents.setdefault(ppid, []).append(int(entry.name))
    tree, todo = [], [root]
    while todo:
        pid = todo.pop()
        tree.append(pid)
        todo.extend(parents.get(pid, []))
    return tree


def rss_mb(pid: int) -> float:
    """Resident memory of ``pid`` (MB; 0 when it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except (OSError, ValueError):
        pass
    return 0.0


class ClockObserver:
    """A node counting ``/clock`` messages by sim time (its newest stamp, ns)."""

    def __init__(self, context) -> None:
        from rclpy.node import Node
        from rosgraph_msgs.msg import Clock

        from rabbit_msgs_py import qos, topics
        from rabbit_msgs_py.conversions import stamp_to_ns

        self.node = Node("soak_clock_observer", context=context)
        self.stamps: list[int] = []
        self.node.create_subscription(Clock, topics.CLOCK, lambda m: self.stamps.append(stamp_to_ns(m.clock)),
                                      qos.CLOCK_QOS)


Sample = tuple[float, float, dict[int, float]]
"""(sim s, RSS MB of the stack's processes together, CPU s of each process by pid)."""


def tenths(samples: list[Sample], duration: float) -> tuple[list[Sample], list[Sample]]:
    """The samples in the first and the last tenth of the walk (start-up, at sim time 0, left out)."""
    first = [s for s in samples if 0.0 < s[0] <= 0.1 * duration]
    last = [s for s in samples if 0.9 * duration <= s[0] < duration]
    return first, last


def cpu_per_tick_us(part: list[Sample]) -> float | None:
    """CPU µs per 1 ms tick between the first and last sample of ``part``, summed over the
    processes alive at both."""
    if len(part) < 2 or part[-1][0] <= part[0][0]:
        return None
    (t0, _, cpu0), (t1, _, cpu1) = part[0], part[-1]
    spent = sum(cpu1[pid] - cpu0[pid] for pid in cpu0.keys() & cpu1.keys())
    return round(spent / ((t1 - t0) * 1000.0) * 1e6, 1)


def hand_started(controller: str, duration: float, pushes: str, stats_file: Path) -> list[list[str]]:
    """The three nodes' command lines as a user would start them by hand (what ``ros2 run``
    executes), for a watched run: the simulator paused until the watcher runs it, halting at
    ``duration`` s, with ``pushes``; the controller writing its counts to ``stats_file``."""
    from rabbit_policy.bringup.config import NODE_MODULES, ros_arguments

    params = {"sim_node": {"start_paused": True, "stop_time": float(duration), "push_schedule": pushes},
              "hzd_controller_node": {"stats_file": str(stats_file)},
              "policy_node": {"policy": controller}}
    return [[sys.executable, "-m", NODE_MODULES[name], *ros_arguments(values)] for name, values in params.items()]


def stop_nodes(procs: list[subprocess.Popen], timeout: float = 10.0) -> None:
    """SIGINT (Ctrl-C) to each, then SIGKILL to any still running after ``timeout`` s."""
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
    for proc in procs:
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def soak(layout: str, controller: str, duration: float, seed: int, impulse: float, record: str,
         log: Path) -> dict[str, object]:
    """One soak run; see the module docstring."""
    import rclpy

    from rabbit_msgs_py.node_runner import init_context, make_executor
    from rabbit_policy.bringup.cpu import process_cpu_seconds
    from rabbit_policy.bringup.processes import signal_on_parent_death

    schedule, pushes = soak_scenario(seed, duration, impulse)
    bag = Path(record) if record else None
    command = [sys.executable, "-m", "rabbit_policy.commands.run_stack", "--speed-schedule", schedule,
               "--duration", str(duration), "--json"]
    command += ["--attach"] if layout == "hand" else ["--controller", controller, "--layout", layout]
    if pushes and layout != "hand":
        command += ["--push", pushes]
    if bag is not None:
        command += ["--record", str(bag)]
    scratch = Path(tempfile.mkdtemp(prefix="rabbit_soak_"))
    nodes: list[subprocess.Popen] = []
    context = init_context()
    observer = ClockObserver(context)
    executor = make_executor(context)
    executor.add_node(observer.node)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    samples: list[Sample] = []
    start = time.perf_counter()
    with open(log, "w") as err, tempfile.TemporaryFile("w+") as report_file:
        # the report to a file, not a pipe: an hour's JSON is larger than a pipe holds, and a
        # run_stack writing into a full pipe nobody reads until it exits would never exit
        # a bench_soak killed outright (SIGTERM, SIGKILL) stops its run_stack as Ctrl-C would (SIGINT:
        # the nodes stopped in order), instead of leaving the stack walking on in the domain
        if layout == "hand":  # the nodes killed with this process, as run_stack's are
            nodes = [subprocess.Popen(line, stdout=err, stderr=err, stdin=subprocess.DEVNULL,
                                      preexec_fn=functools.partial(signal_on_parent_death, signal.SIGINT))
                     for line in hand_started(controller, duration, pushes, scratch / "controller.json")]
        proc = subprocess.Popen(command, stdout=report_file, stderr=err, text=True,
                                preexec_fn=functools.partial(signal_on_parent_death, signal.SIGINT))
        while proc.poll() is None:
            time.sleep(SAMPLE_EVERY)
            pids = [pid for root in [proc.pid] + [n.pid for n in nodes] for pid in process_tree(root)]
            cpu = {p: process_cpu_seconds(p) for p in pids}
            sim = observer.stamps[-1] / 1e9 if observer.stamps else 0.0
            samples.append((sim, sum(rss_mb(p) for p in pids), {p: c for p, c in cpu.items() if c is not None}))
        report_file.seek(0)
        out = report_file.read()
        stop_nodes(nodes)
    wall = time.perf_counter() - start
    counts = controller_counts(str(scratch / "controller.json")) if layout == "hand" else None
    shutil.rmtree(scratch, ignore_errors=True)
    stop.set()
    spinner.join(timeout=5.0)
    executor.shutdown()
    observer.node.destroy_node()
    rclpy.shutdown(context=context)
    report = json.loads(out)
    recorded = None
    if bag is not None and bag.exists():
        from rabbit_sim.bag import joint_state_stamps

        recorded = len(joint_state_stamps(bag))
    segments = report["segments"]
    unreached = [{"start": s["start"], "command": s["command"]} for s in segments if s["reach_time"] is None]
    per_tenth = [0] * 10
    for stamp in observer.stamps:
        k = min(9, int(stamp / 1e9 / duration * 10))
        per_tenth[k] += 1
    due = duration / 10 * CLOCK_RATE
    first, last = tenths(samples, duration)
    simulated = int(round(report["duration"] * 1000)) + 1  # ticks, the placed state too
    return {
        "layout": layout, "controller": controller, "duration_s": duration, "seed": seed,
        "push_impulse_Ns": impulse, "pushes": len(pushes.split(",")) if pushes else 0,
        "completed": report["completed"], "error": report["error"], "fell": report["fell"],
        "stalled": report["stalled"], "sim_s": report["duration"], "wall_s": round(wall, 1),
        "real_time_factor": report["real_time_factor"], "decisions_lost": report["decisions_lost"],
        # hand: the controller's own count at its close (the watcher's is from /hzd/decisions_lost); None: no file
        "decisions_lost_stats_file": None if counts is None else
        int(counts.get("decisions_timed_out", 0)) + int(counts.get("policy_silences", 0)),
        "commands": len(segments), "commands_reached": len(segments) - len(unreached), "unreached": unreached,
        "last_command_reached": report["last_command_reached"],
        "clock_fraction_by_tenth": [round(n / due, 3) for n in per_tenth],
        "clock_fraction_min": round(min(per_tenth) / due, 3),
        "rss_mb_first_tenth": round(sum(s[1] for s in first) / len(first), 1) if first else None,
        "rss_mb_last_tenth": round(sum(s[1] for s in last) / len(last), 1) if last else None,
        "cpu_us_per_tick_first_tenth": cpu_per_tick_us(first), "cpu_us_per_tick_last_tenth": cpu_per_tick_us(last),
        "recorded_states": recorded, "states_lost": None if recorded is None else simulated - recorded,
    }


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--layout", choices=("composed", "separate", "in-process", "hand"), default="composed",
                        help="run_stack's layouts, or hand: three nodes started as by ros2 run, watched by "
                             "run_stack --attach (default composed)")
    parser.add_argument("--controller", type=controller_argument, default="learned",
                        metavar="{classic,learned,recovery}")
    parser.add_argument("--duration", type=positive, default=3600.0, help="sim s (default 3600: an hour)")
    parser.add_argument("--seed", type=int, default=0, help="the scenario's draw (default 0)")
    parser.add_argument("--push-impulse", type=positive, default=3.0, metavar="NS",
                        help="each push's impulse, N s over 0.1 s (default 3)")
    parser.add_argument("--record", default="", metavar="DIR",
                        help="record the run to a rosbag2 bag in DIR (must not exist) and count the states lost")
    parser.add_argument("--log", default="", metavar="FILE", help="the stack's log (default: a temporary file)")
    return parser


def main(argv: list[str] | None = None) -> int:
    ensure_localhost_discovery()
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.record and args.layout == "hand":
        parser.error("--record: a stack started by hand records with its own recorder_node (--layout hand runs none)")
    problem = unwritable_dir(Path(args.record).resolve().parent) if args.record else None
    if problem:
        parser.error(f"--record {args.record}: {problem}")
    log = Path(args.log) if args.log else Path(tempfile.mkstemp(prefix="rabbit_soak_", suffix=".log")[1])
    try:
        log.parent.mkdir(parents=True, exist_ok=True)
        log.touch()
    except OSError as exc:
        print(f"error: --log {args.log}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    result = soak(args.layout, args.controller, args.duration, args.seed, args.push_impulse, args.record, log)
    result["log"] = str(log)
    print(strict_json.dumps(result))
    return 0 if result["completed"] and not (result["fell"] or result["stalled"]) else 1


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    sys.exit(main())
