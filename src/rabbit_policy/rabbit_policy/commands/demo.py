"""``make demo``: the ROS 2 stack walks RABBIT on the learned controller, then the same scenario
runs on classic HZD (the ROS-free fast path, which a lockstep run equals bit for bit), and the
two are judged side by side against a stated tolerance.

    scripts/demo.py [--controller learned] [--tolerance 0.03]

The scenario: 0.8 -> 1.4 -> 0.9 -> 1.2 m/s (changes at 6, 13 and 18 s) with a 6 N s backward
push at 20 s, 26 s in all. Per segment: the commanded speed, each controller's mean over the
segment's second half and the time to reach the command (the first whole step within 0.05 m/s,
``rabbit_policy.experiment.result``), and whether the mean is within ``--tolerance`` of the
command; then one closing line. Exit status: run_stack's (0 walked and reached the last
command; ``run_stack.py --help``).
"""

from __future__ import annotations

import json
import subprocess
import sys

from rabbit_msgs_py.cli import ArgumentParser, positive
from rabbit_policy.runtime.policies import controller_argument

SCENARIO = ["--speed-schedule", "0:0.8,6:1.4,13:0.9,18:1.2", "--push", "20:-60:0.1", "--duration", "26"]
"""The demo's walk, as run_stack.py and walk.py take it."""
BASELINE = "classic"


def run_json(module: str, controller: str) -> tuple[dict, int]:
    """``python -m MODULE --controller C SCENARIO --json``: its report and exit status (its log on stderr)."""
    out = subprocess.run([sys.executable, "-m", module, "--controller", controller, *SCENARIO, "--json"],
                         stdout=subprocess.PIPE, text=True)
    return json.loads(out.stdout), out.returncode


def within(segment: dict, tolerance: float) -> bool:
    """The segment's second-half mean is within ``tolerance`` m/s of its command."""
    mean = segment["mean_speed"]
    return mean is not None and abs(mean - segment["command"]) <= tolerance


def judge(reports: dict[str, dict], tolerance: float) -> list[str]:
    """The side-by-side table and the closing line (text lines)."""
    names = list(reports)
    lines = ["segment          command  " + "  ".join(f"{n:>22}" for n in names),
             "                   (m/s)  " + "  ".join(f"{'mean m/s, reached in':>22}" for _ in names)]
    rows = zip(*(reports[n]["segments"] for n in names))
    for segments in rows:
        first = segments[0]
        cells = []
        for seg in segments:
            mean = "   n/a" if seg["mean_speed"] is None else f"{seg['mean_speed']:6.3f}"
            reach = "never" if seg["reach_time"] is None else f"{seg['reach_time']:.2f} s"
            cells.append(f"{mean} {'ok' if within(seg, tolerance) else 'off':>3}, {reach:>8}")
        lines.append(f"{first['start']:5.1f}-{first['end']:5.1f} s    {first['command']:5.2f}  "
                     + "  ".join(f"{c:>22}" for c in cells))
    counts = [f"{n} {sum(within(s, tolerance) for s in reports[n]['segments'])}/{len(reports[n]['segments'])}"
              for n in names]
    outcome = ", ".join(f"{n} {'fell' if r['fell'] else 'stalled' if r['stalled'] else 'walked'}"
                        for n, r in reports.items())
    lines.append(f"segments whose mean is within {tolerance:g} m/s of the command: {'; '.join(counts)} ({outcome})")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__)
    parser.add_argument("--controller", type=controller_argument, default="learned", metavar="{classic,learned,recovery}",
                        help="the controller the ROS 2 stack runs (default learned)")
    parser.add_argument("--tolerance", type=positive, default=0.03, metavar="M_S",
                        help="how close a segment's mean must be to its command, m/s (default 0.03)")
    args = parser.parse_args(argv)
    print(f"demo: the ROS 2 stack on {args.controller} ({' '.join(SCENARIO)}); then {BASELINE} on the fast path",
          file=sys.stderr, flush=True)
    stack, status = run_json("rabbit_policy.commands.run_stack", args.controller)
    if stack["duration"] == 0.0:
        print(f"error: the stack did not run: {stack['error']}", file=sys.stderr)
        return status
    reports = {f"{args.controller} (ROS 2)": stack}
    if args.controller != BASELINE:
        reports[f"{BASELINE} (fast path)"] = run_json("rabbit_policy.commands.walk", BASELINE)[0]
    print("\n".join(judge(reports, args.tolerance)))
    rtf = stack.get("real_time_factor")
    print(f"the stack: {stack['steps']} steps, real-time factor {rtf if rtf is not None else 'n/a'}"
          + ("" if stack["completed"] else f", incomplete: {stack['error']}"))
    return status


if __name__ == "__main__":
    sys.exit(main())
