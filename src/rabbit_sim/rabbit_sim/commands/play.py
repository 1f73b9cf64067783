"""Replay a recorded bag on its topics, as ``ros2 bag play`` does (which is C++ and not on PyPI).

    scripts/play.py runs/walk1                        # every topic, at the recorded pace
    scripts/play.py runs/walk1 --rate 0.5 --loop      # half speed, over and over
    scripts/play.py runs/walk1 --topics /joint_states /rabbit/markers --clock 100

Every topic is published with its recorded type and QoS (reliability, durability), the
recorded bytes as they are, paced by the bag's log time divided by ``--rate``. ``--clock
[HZ]`` publishes ``/clock`` from the log time (default 40 Hz) instead of the bag's own
``/clock``, for nodes with ``use_sim_time``. ``--delay`` waits that long after creating the
publishers so subscribers (Foxglove, RViz, a recorder) discover them first. Ctrl-C stops.
Exit status: 0 played, 1 interrupted, 2 bad arguments or a bag that cannot be played.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from rabbit_msgs_py.cli import ArgumentParser
from rabbit_msgs_py.environment import ensure_localhost_discovery


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("bag", help="rosbag2 bag directory (metadata.yaml + MCAP)")
    parser.add_argument("--rate", type=float, default=1.0, help="playback speed factor (> 0; 2 = twice as fast)")
    parser.add_argument("--loop", action="store_true", help="play again from the start until Ctrl-C")
    parser.add_argument("--topics", nargs="+", default=None, help="only these topics (default: all)")
    parser.add_argument("--clock", type=float, nargs="?", const=40.0, default=0.0, metavar="HZ",
                        help="publish /clock from the log time at HZ (default 40) instead of the bag's /clock")
    parser.add_argument("--delay", type=float, default=1.0, help="s to wait for subscribers before playing (>= 0)")
    parser.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="S",
                        help="after --delay, wait up to S s until every played topic has a subscriber, and at the "
                             "end up to S s until every subscriber acknowledged every reliable message (0 = don't)")
    return parser


def main(argv: list[str] | None = None) -> int:
    ensure_localhost_discovery()
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.rate > 0.0 or args.clock < 0.0 or args.delay < 0.0 or args.wait_for_subscribers < 0.0:
        parser.error("--rate must be > 0, --clock, --delay and --wait-for-subscribers >= 0")

    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from rabbit_sim.bag import BagError
    from rabbit_sim.player import BagPlayer

    stopping = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stopping.append(True))
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    player = None
    try:
        try:
            player = BagPlayer(Path(args.bag), args.topics, args.rate, args.clock, context=context,
                               log=lambda line: print(line, file=sys.stderr))
        except BagError as exc:  # not a bag, unreadable, a topic it lacks (PlaybackError)
            print(f"error: {exc}", file=sys.stderr)
            return 2
        deadline = time.perf_counter() + args.delay
        while time.perf_counter() < deadline and not stopping:
            time.sleep(0.02)
        if args.wait_for_subscribers and not player.wait_for_subscribers(args.wait_for_subscribers):
            print(f"warning: not every topic had a subscriber after {args.wait_for_subscribers:g} s; playing anyway",
                  file=sys.stderr)
        print(f"playing {args.bag}: {len(player.topics)} topics at rate {args.rate}"
              + (f", /clock at {args.clock:g} Hz" if args.clock else ""), file=sys.stderr)
        finished = True
        while not stopping:
            finished = player.play(stop=lambda: bool(stopping))
            if not args.loop:
                break
        if args.wait_for_subscribers and not player.wait_for_acknowledgements(args.wait_for_subscribers):
            print("warning: not every reliable message was acknowledged by its subscribers", file=sys.stderr)
        print(f"published {sum(player.published.values())} messages"
              + (f" and {player.clocks_published} clocks" if args.clock else ""), file=sys.stderr)
        return 0 if finished and not stopping else 1
    finally:
        if player is not None:
            player.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)


if __name__ == "__main__":
    sys.exit(main())
