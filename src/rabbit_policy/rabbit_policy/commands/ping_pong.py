"""The floor under the 1 kHz stack: how many round trips of one small message two rclpy nodes
make per wall second over the same middleware and executor the stack uses (rclpy's
``EventsExecutor``, Fast DDS, localhost). A lockstep tick is one such round trip at least
(a state out, a torque back), so ``bench_stack`` reports each mode's ticks per second as a
ratio to it, measured in the same run: a ratio carries to another machine, a rate does not.

* :func:`round_trips_per_s` with ``same_process=False``: the echoing node in a child
  process (``python -m rabbit_policy.commands.ping_pong --echo TOPIC``), as the stack's nodes
  run under ``ros2 run``;
* ``same_process=True``: both nodes on one executor in this process, as run_stack's
  in-process layout.

The message is a ``std_msgs/UInt64`` counter on reliable, keep-last-1 topics
(``TOPIC/ping`` and ``TOPIC/pong``); the pinger sends the next once the echo of the last is
in. The count is over ``seconds`` of wall time after ``warm_up`` s."""

from __future__ import annotations

import os
import subprocess
import sys
import time


def _qos():
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)


def echo_node(context, topic: str):
    """A node that answers every ``TOPIC/ping`` with the same number on ``TOPIC/pong``."""
    import rclpy
    from std_msgs.msg import UInt64

    node = rclpy.create_node("ping_pong_echo", context=context)
    pong = node.create_publisher(UInt64, f"{topic}/pong", _qos())
    node.create_subscription(UInt64, f"{topic}/ping", pong.publish, _qos())
    return node


def round_trips_per_s(seconds: float = 3.0, same_process: bool = False, warm_up: float = 1.0,
                      timeout: float = 30.0) -> float:
    """Round trips per wall second (see the module docstring); ``RuntimeError`` when the echo
    does not answer within ``timeout`` s."""
    import rclpy
    from std_msgs.msg import UInt64

    from rabbit_msgs_py.node_runner import init_context, make_executor

    topic = f"/ping_pong_{os.getpid()}"
    context = init_context()
    executor = make_executor(context)
    child = None
    try:
        node = rclpy.create_node("ping_pong", context=context)
        executor.add_node(node)
        if same_process:
            executor.add_node(echo_node(context, topic))
        else:
            child = subprocess.Popen([sys.executable, "-m", "rabbit_policy.commands.ping_pong", "--echo", topic])
        ping = node.create_publisher(UInt64, f"{topic}/ping", _qos())
        counted = {"n": 0}

        def on_pong(msg: UInt64) -> None:
            counted["n"] += 1
            ping.publish(UInt64(data=msg.data + 1))

        node.create_subscription(UInt64, f"{topic}/pong", on_pong, _qos())
        deadline = time.monotonic() + timeout
        while counted["n"] == 0:  # until the echo is matched both ways: ping again until one comes back
            if time.monotonic() > deadline:
                raise RuntimeError("the ping-pong echo did not answer")
            ping.publish(UInt64(data=0))
            executor.spin_once(timeout_sec=0.05)
        _spin_for(executor, warm_up)
        start_count, start = counted["n"], time.monotonic()
        _spin_for(executor, seconds)
        return (counted["n"] - start_count) / (time.monotonic() - start)
    finally:
        if child is not None:
            child.terminate()
            child.wait(timeout=10)
        executor.shutdown()
        context.try_shutdown()


def _spin_for(executor, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.01)


def main(argv: list[str] | None = None) -> int:
    """``--echo TOPIC``: run the echoing node until SIGTERM or SIGINT."""
    from rabbit_msgs_py.cli import ArgumentParser
    from rabbit_msgs_py.node_runner import run_node

    parser = ArgumentParser(description=__doc__)
    parser.add_argument("--echo", required=True, metavar="TOPIC", help="answer TOPIC/ping on TOPIC/pong")
    args = parser.parse_args(argv)
    return run_node(lambda context: echo_node(context, args.echo), [])


if __name__ == "__main__":
    sys.exit(main())
