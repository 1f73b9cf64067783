"""Benchmark the ROS 2 stack; prints one JSON object.

* ``floor_round_trips_per_s_multi_process`` / ``_in_process``: the rclpy ping-pong floor
  (:mod:`rabbit_policy.commands.ping_pong`: round trips of one small message per wall second
  between two nodes, in two processes / on one executor), and ``*_to_floor``: each lockstep
  and paced mode's ticks per second over the floor of its layout, measured in the same run
  (a ratio carries to another machine).

* ``lockstep_rtf_in_process``: real-time factor (sim s / wall s) of a lockstep walk with
  all nodes on one EventsExecutor in this process.
* ``lockstep_rtf_multi_process``: the same with every node its own process (``--layout
  separate``).
* ``lockstep_rtf_composed``: the same in run_stack's default layout (simulator, controller and
  supervisor in one process, the policy in its own).
* ``*_cpu_us_per_tick``: each process's CPU time (user + system, all threads) per tick over
  the walk, and their total (``/proc``; Linux).
* realtime mode, run_stack's default layout: ``realtime_rate_hz`` (physics/control ticks
  per wall second), ``realtime_late_fraction`` (share of ticks whose torque, the reply to
  the previous state, had not arrived when the step was due; goal < 1 %),
  ``latency_p50_ms`` / ``latency_p99_ms`` (state published -> its torque received, as
  seen by sim_node), ``realtime_damped_ticks``.

* ``realtime_in_process_*``: the realtime run with all nodes in this process.
* ``paced_*``: paced mode (lockstep held to the wall clock, ``--rtf`` target), run_stack's
  default layout: the achieved real-time factor (sim s / wall s over the run), whether
  it fell, and with ``--record`` (``paced_recording_*``) the states lost: distinct
  ``/joint_states`` ticks simulated minus those in the bag (0 by design).
* Realtime runs halt when the loop falls too far behind (``*_halted``: the reason, or None).
* ``--busy N`` runs N busy loops (``while True: pass``) beside every scenario: a loaded machine.
* ``recorder_*``: the realtime run (default layout) with ``--record``: the recorder process's
  CPU share (CPU s / wall s over its life), messages written per wall second (its life
  includes start-up and shutdown, so this understates the rate during the walk), and
  /joint_states recorded vs published.

* ``startup_to_physics_s``: wall s from launching ``scripts/run_stack.py`` to sim_node's
  "simulation running" log line (its ROS timestamp), the median of 3 launches, and
  ``startup_warnings``: WARN/ERROR lines those launches logged (0 on a normal start).

* ``stop_after_sigint_s``: per node (sim_node, hzd_controller_node, policy_node,
  recorder_node, each ``python -m`` in a process group of its own, as a terminal starts it), wall
  s from SIGINT to the group to the process's exit, once it has started (the recorder with
  its bag closed), the median of 3.

* ``flood_*``: what a flood costs the lockstep loop, per layout (in-process, composed,
  multi-process): ``flood_<layout>_rtf`` with a process publishing 30 NaN values as a
  ``Float64MultiArray`` on ``/sim/state_batch`` at 10 kHz (reliable, as the observers
  subscribe; every one is refused), ``flood_<layout>_baseline_rtf`` with one busy loop in its
  place (the flooder's own CPU, so the ratio is what the stack pays), their ratio
  (``_ratio``; issue 75's bar: at least 0.5), ``flood_<layout>_sent_per_s`` (as sent) and
  whether the flooded walk completed. ``--flood-topic`` floods another topic a node subscribes
  to instead (:data:`FLOOD_TOPICS`: what each sends, each refused where it arrives), its keys
  ``flood_<layout>_<topic>_...``; ``--flood-topic all`` runs each in turn.

RTFs are measured from the first to the last state the supervisor saw (start-up
excluded). Usage: scripts/bench_stack.py [--duration 10] [--realtime-duration 10]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import ArgumentParser, positive
from rabbit_msgs_py.environment import ensure_localhost_discovery


SCENARIOS = ("floor", "startup", "stop", "lockstep_in_process", "lockstep_composed", "lockstep_multi_process",
             "paced_multi_process", "paced_recording",
             "realtime_multi_process", "realtime_in_process", "realtime_recording",
             "flood_in_process", "flood_composed", "flood_multi_process")

FLOOD_RATE = 10_000.0
"""Hz: the flood scenarios' messages a second (issue 75's hostile user)."""
FLOOD_LAYOUTS = {"flood_in_process": "in-process", "flood_composed": "composed", "flood_multi_process": "separate"}
FLOOD_TOPICS = {
    "state_batch": "/sim/state_batch: a Float64MultiArray of 30 NaN (the policy and the supervisor refuse it)",
    "joint_states": "/joint_states: a JointState of 7 NaN positions (the controller refuses it)",
    "joint_torques": "/joint_torques: a JointState of 4 NaN efforts, unsigned (the simulator refuses it)",
    "alpha": "/hzd/alpha: a 4 x 6 Float64MultiArray of zeros, unsigned (the controller refuses it)",
    "gait_timing": "/hzd/gait_timing: 'at_once:7', unsigned (the controller refuses it)",
    "cmd_speed": "/cmd_speed: NaN (the policy refuses it)",
    "phase": "/hzd/phase: a JointState phase of NaN (the policy refuses it)",
}
"""What ``--flood-topic`` floods: the topics the stack's nodes subscribe to, each with a message
its subscriber refuses."""


def rounded(value: float | None, digits: int) -> float | None:
    """``round`` that passes None (a statistic without data) through."""
    return None if value is None else round(value, digits)


def recorded_ticks(bag: Path) -> int:
    """Distinct /joint_states stamps in a bag."""
    from rabbit_sim.bag import joint_state_stamps

    return len(joint_state_stamps(bag))


def startup(launches: int = 3) -> dict[str, object]:
    """Wall s from launching run_stack to the physics running (median), and the warnings."""
    import re
    import statistics
    import time

    delays, warnings = [], 0
    for _ in range(launches):
        start = time.time()
        result = subprocess.run([sys.executable, "-m", "rabbit_policy.commands.run_stack", "--duration", "1", "--json"], capture_output=True,
                                text=True)
        running = re.search(r"\[(\d+\.\d+)\] \[[\w.]*sim_node\]: simulation running", result.stderr)
        if result.returncode != 0 or running is None:
            raise RuntimeError(f"run_stack failed (status {result.returncode}): {result.stderr[-500:]}")
        delays.append(float(running.group(1)) - start)
        warnings += len(re.findall(r"^\[(WARN|ERROR)\]", result.stderr, re.M))
    return {"startup_to_physics_s": round(statistics.median(delays), 2), "startup_warnings": warnings}


STOPPED_NODES = {"sim_node": ("rabbit_sim.sim_node", "waiting for a state"),
                 "hzd_controller_node": ("rabbit_hzd_controller.hzd_controller_node", "waiting for a gait"),
                 "policy_node": ("rabbit_policy.policy_node", "send speeds on"),
                 "recorder_node": ("rabbit_sim.recorder_node", "recording")}
"""Each node's module and the log line that says it has started."""


def stop_times(repeats: int = 3) -> dict[str, object]:
    """Wall s from SIGINT (to the node's process group, as Ctrl-C in a terminal sends it) to
    each node's exit, median of ``repeats``; the recorder's bag must be closed by then."""
    import os
    import signal
    import statistics
    import time

    times: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (module, started) in STOPPED_NODES.items():
            runs = []
            for k in range(repeats):
                args = ["--ros-args", "-p", f"output:={tmp}/bag{k}"] if name == "recorder_node" else []
                node = subprocess.Popen([sys.executable, "-m", module, *args], stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True, start_new_session=True)
                for line in node.stdout:
                    if started in line:
                        break
                time.sleep(0.5)
                sent = time.monotonic()
                os.killpg(node.pid, signal.SIGINT)
                tail = node.communicate(timeout=60)[0]
                runs.append(time.monotonic() - sent)
                if node.returncode not in (0, -signal.SIGINT) or (name == "recorder_node" and "closed" not in tail):
                    raise RuntimeError(f"{name} did not stop cleanly (status {node.returncode}): {tail[-500:]}")
            times[name] = round(statistics.median(runs), 3)
    return {"stop_after_sigint_s": times}


def run_scenario(name: str, duration: float, realtime_duration: float, speed: float,
                 rtf: float = 1.0, flood_topic: str = "state_batch") -> dict[str, object]:
    """One measurement; each runs in a fresh interpreter (see main)."""
    from rabbit_policy.bringup.config import StackConfig
    from rabbit_policy.bringup.in_process import run_in_process
    from rabbit_policy.bringup.processes import run_multi_process

    if name == "floor":
        from rabbit_policy.commands.ping_pong import round_trips_per_s

        return {"floor_round_trips_per_s_multi_process": round(round_trips_per_s(3.0), 1),
                "floor_round_trips_per_s_in_process": round(round_trips_per_s(3.0, same_process=True), 1)}
    if name == "startup":
        return startup()
    if name == "stop":
        return stop_times()
    schedule = ((0.0, speed),)
    if name in ("paced_multi_process", "paced_recording"):
        prefix = "paced" if name == "paced_multi_process" else "paced_recording"
        with tempfile.TemporaryDirectory() as tmp:
            sim_stats = Path(tmp) / "sim.json"
            bag = Path(tmp) / "bag" if name == "paced_recording" else None
            config = StackConfig(duration=realtime_duration, schedule=schedule, mode="paced", rtf=rtf,
                                 stats_file=str(sim_stats), record=str(bag) if bag else "")
            report = run_multi_process(config, log=sys.stderr)
            sim = json.loads(sim_stats.read_text())
            out = {f"{prefix}_rtf": round(report.rtf, 3), f"{prefix}_target_rtf": rtf, f"{prefix}_fell": report.fell,
                   f"{prefix}_completed": report.completed, f"{prefix}_cpu_us_per_tick": report.cpu_us_per_tick}
            if bag is not None:
                out[f"{prefix}_states_lost"] = sim["ticks"] + 1 - recorded_ticks(bag)
            return out
    if name == "lockstep_in_process":
        report, _ = run_in_process(StackConfig(duration=duration, schedule=schedule))
        return {"lockstep_rtf_in_process": round(report.rtf, 3), "lockstep_in_process_fell": report.fell,
                "lockstep_in_process_cpu_us_per_tick": report.cpu_us_per_tick}
    if name in ("lockstep_multi_process", "lockstep_composed"):
        layout = "separate" if name == "lockstep_multi_process" else "composed"
        report = run_multi_process(StackConfig(duration=duration, schedule=schedule, layout=layout), log=sys.stderr)
        return {f"lockstep_rtf_{name[9:]}": round(report.rtf, 3), f"{name}_fell": report.fell,
                f"{name}_cpu_us_per_tick": report.cpu_us_per_tick}
    if name in FLOOD_LAYOUTS:
        return flood(name, StackConfig(duration=duration, schedule=schedule, layout=FLOOD_LAYOUTS[name]), flood_topic)
    if name == "realtime_in_process":
        report, nodes = run_in_process(StackConfig(duration=realtime_duration, schedule=schedule, mode="realtime"))
        stats = nodes["sim_node"].statistics()
        return {
            "realtime_in_process_late_fraction": rounded(stats["late_fraction"], 5),
            "realtime_in_process_latency_p50_ms": rounded(stats["latency_p50_ms"], 3),
            "realtime_in_process_latency_p99_ms": rounded(stats["latency_p99_ms"], 3),
            "realtime_in_process_worst_delay_ms": rounded(stats["latency_max_ms"], 3),
            "realtime_in_process_skipped_ticks": stats["skipped_ticks"],
            "realtime_in_process_fell": report.fell,
            "realtime_in_process_halted": stats["halt_reason"],
        }
    if name == "realtime_recording":
        with tempfile.TemporaryDirectory() as tmp:
            sim_stats, rec_stats = Path(tmp) / "sim.json", Path(tmp) / "rec.json"
            config = StackConfig(duration=realtime_duration, schedule=schedule, mode="realtime",
                                 stats_file=str(sim_stats), record=str(Path(tmp) / "bag"),
                                 record_stats_file=str(rec_stats))
            report = run_multi_process(config, log=sys.stderr)
            sim, rec = json.loads(sim_stats.read_text()), json.loads(rec_stats.read_text())
        return {
            "recorder_cpu_share": round(rec["cpu_share"], 3),
            "recorder_msgs_per_s": round(rec["messages"] / rec["wall_s"], 1),
            "recorder_joint_states_recorded": rec["counts"]["/joint_states"],
            "recorder_joint_states_published": sim["states_published"],
            "recorder_realtime_late_fraction": rounded(sim["late_fraction"], 5),
            "recorder_run_fell": report.fell,
            "recorder_realtime_halted": sim["halt_reason"],
        }
    with tempfile.TemporaryDirectory() as tmp:
        stats_path = Path(tmp) / "sim_stats.json"
        config = StackConfig(duration=realtime_duration, schedule=schedule, mode="realtime", stats_file=str(stats_path))
        report = run_multi_process(config, log=sys.stderr)
        stats = json.loads(stats_path.read_text())
    return {
        "realtime_rtf": round(report.rtf, 3),
        "realtime_rate_hz": rounded(stats["tick_rate_hz"], 1),
        "realtime_late_fraction": rounded(stats["late_fraction"], 5),
        "latency_p50_ms": rounded(stats["latency_p50_ms"], 3),
        "latency_p99_ms": rounded(stats["latency_p99_ms"], 3),
        "worst_delay_ms": rounded(stats["latency_max_ms"], 3),
        "realtime_skipped_ticks": stats["skipped_ticks"],
        "realtime_ticks": stats["ticks"],
        "realtime_damped_ticks": stats["damped_ticks"],
        "realtime_fell": report.fell,
        "realtime_halted": stats["halt_reason"],
    }


def flood(name: str, config, topic: str = "state_batch") -> dict[str, object]:
    """The lockstep walk of ``config`` beside a busy loop, then beside a 10 kHz flooder of
    ``topic`` (:data:`FLOOD_TOPICS`; see the module docstring)."""
    from rabbit_policy.bringup.in_process import run_in_process
    from rabbit_policy.bringup.processes import run_multi_process

    def walk():
        return run_in_process(config)[0] if config.layout == "in-process" else run_multi_process(config, log=sys.stderr)

    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        baseline = walk()
    finally:
        busy.kill()
    flooder = subprocess.Popen([sys.executable, "-m", "rabbit_policy.commands.bench_stack", "--flooder",
                                "--flood-topic", topic], stdout=subprocess.PIPE, text=True)
    try:
        flooded = walk()
    finally:
        flooder.terminate()
        try:
            out = flooder.communicate(timeout=30)[0]
        except subprocess.TimeoutExpired:
            flooder.kill()
            raise
    sent = json.loads(out.strip().splitlines()[-1])
    name = name if topic == "state_batch" else f"{name}_{topic}"  # (state_batch: the keys measured first)
    return {f"{name}_baseline_rtf": round(baseline.rtf, 3), f"{name}_rtf": round(flooded.rtf, 3),
            f"{name}_ratio": round(flooded.rtf / baseline.rtf, 3), f"{name}_sent_per_s": sent["per_s"],
            f"{name}_completed": flooded.completed and not flooded.fell and not flooded.stalled}


def flood_message(topic: str):
    """(message type, topic name, QoS, the message) of :data:`FLOOD_TOPICS`' ``topic``, each
    on its subscribers' QoS."""
    import math

    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64, Float64MultiArray, String

    from rabbit_msgs_py import qos, topics
    from rabbit_msgs_py.joints import ACTUATED_JOINTS, JOINT_NAMES

    nan = math.nan
    return {
        "state_batch": (Float64MultiArray, topics.STATE_BATCH, qos.BATCH_QOS, Float64MultiArray(data=[nan] * 30)),
        "joint_states": (JointState, topics.JOINT_STATES, qos.STREAM_QOS,
                         JointState(name=list(JOINT_NAMES), position=[nan] * 7, velocity=[0.0] * 7)),
        "joint_torques": (JointState, topics.JOINT_TORQUES, qos.TORQUE_QOS,
                          JointState(name=list(ACTUATED_JOINTS), effort=[nan] * 4)),
        "alpha": (Float64MultiArray, topics.ALPHA, qos.GAIT_QOS, Float64MultiArray(data=[0.0] * 24)),
        "gait_timing": (String, topics.GAIT_TIMING, qos.GAIT_QOS, String(data="at_once:7")),
        "cmd_speed": (Float64, topics.CMD_SPEED, qos.COMMAND_QOS, Float64(data=nan)),
        "phase": (JointState, topics.PHASE, qos.STREAM_QOS, JointState(name=["gait_phase"], position=[nan],
                                                                         velocity=[nan])),
    }[topic]


def flooder(rate: float = FLOOD_RATE, topic: str = "state_batch") -> dict[str, float]:
    """Publish ``topic``'s message (:func:`flood_message`) at ``rate`` Hz until SIGTERM (a
    handler of its own: a process started in the background inherits SIGINT ignored); returns
    what was sent (``sent``, ``per_s``)."""
    import signal
    import time

    import rclpy

    from rabbit_msgs_py.node_runner import init_context

    context = init_context()
    node = rclpy.create_node("bench_flooder", context=context)
    kind, name, profile, message = flood_message(topic)
    publisher = node.create_publisher(kind, "/" + name, profile)
    stopped: list[int] = []
    signal.signal(signal.SIGTERM, lambda signum, _frame: stopped.append(signum))
    print(f"flooding {publisher.topic_name} at {rate:g} Hz until SIGTERM", file=sys.stderr, flush=True)
    sent, start = 0, time.monotonic()
    try:
        while not stopped:
            publisher.publish(message)
            sent += 1
            ahead = start + sent / rate - time.monotonic()
            if ahead > 0:
                time.sleep(ahead)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
    return {"sent": sent, "per_s": round(sent / (time.monotonic() - start), 1)}


FLOOR_RATIOS = {"lockstep_in_process_to_floor": ("lockstep_rtf_in_process", "in_process"),
                "lockstep_multi_process_to_floor": ("lockstep_rtf_multi_process", "multi_process"),
                "lockstep_composed_to_floor": ("lockstep_rtf_composed", "multi_process"),
                "paced_to_floor": ("paced_rtf", "multi_process")}
"""Each mode's ticks per wall second (1000 x its real-time factor) over the round trips per
second of the ping-pong floor of its layout, measured in the same run."""


def floor_ratios(out: dict) -> dict:
    """:data:`FLOOR_RATIOS` of what ``out`` holds (a ratio whose parts were not measured: left out)."""
    ratios = {}
    for name, (rtf_key, layout) in FLOOR_RATIOS.items():
        floor = out.get(f"floor_round_trips_per_s_{layout}")
        if out.get(rtf_key) is not None and floor:
            ratios[name] = round(1000.0 * out[rtf_key] / floor, 3)
    return ratios


def main(argv: list[str] | None = None) -> int:
    ensure_localhost_discovery()
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=positive, default=10.0, help="lockstep runs, sim s")
    parser.add_argument("--realtime-duration", type=positive, default=10.0, help="realtime runs, s")
    parser.add_argument("--speed", type=positive, default=1.0, help="commanded speed (m/s)")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--flooder", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--flood-topic", choices=(*FLOOD_TOPICS, "all"), default="state_batch",
                        help="what the flood scenarios flood (default state_batch; all: each in turn)")
    parser.add_argument("--rtf", type=positive, default=1.0, help="paced runs: target real-time factor")
    parser.add_argument("--busy", type=int, default=0, metavar="N", help="busy loops beside every scenario")
    parser.add_argument("--only", choices=SCENARIOS, action="append",
                        help="run only this scenario (repeatable)")
    args = parser.parse_args(argv)
    if args.flooder:
        print(strict_json.dumps(flooder(topic=args.flood_topic)))
        return 0
    if args.child:
        print(strict_json.dumps(run_scenario(args.only[0], args.duration, args.realtime_duration, args.speed,
                                             args.rtf, args.flood_topic)))
        return 0
    # every scenario in a fresh interpreter: a run must not inherit another's ROS state
    out: dict[str, object] = {}
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    try:
        flood_topics = tuple(FLOOD_TOPICS) if args.flood_topic == "all" else (args.flood_topic,)
        runs = [(name, topic) for name in args.only or SCENARIOS
                for topic in (flood_topics if name in FLOOD_LAYOUTS else ("state_batch",))]
        for name, topic in runs:
            cmd = [sys.executable, "-m", "rabbit_policy.commands.bench_stack", "--child", "--only", name, "--duration", str(args.duration),
                   "--realtime-duration", str(args.realtime_duration), "--speed", str(args.speed),
                   "--rtf", str(args.rtf), "--flood-topic", topic]
            result = subprocess.run(cmd, stdout=subprocess.PIPE, text=True)
            if result.returncode != 0:
                print(f"error: scenario {name} failed with status {result.returncode}", file=sys.stderr)
                return 1
            out.update(json.loads(result.stdout.strip().splitlines()[-1]))
    finally:
        for hog in hogs:
            hog.kill()
    out.update(floor_ratios(out))
    out.update({"duration_s": args.duration, "realtime_duration_s": args.realtime_duration, "busy_loops": args.busy,
                "executor": "EventsExecutor"})
    print(strict_json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
