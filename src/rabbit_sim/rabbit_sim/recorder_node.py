"""``recorder_node``: records the stack's topics to a rosbag2 bag (MCAP storage).

Subscribes to every stack topic (``rabbit_msgs_py.catalog``) or the ``topics`` parameter's
list, takes messages *serialized* (no deserialisation on the hot path) and writes them with
:class:`rabbit_sim.bag.BagWriter`. Parameters:

* ``output`` (required): bag directory to create; an existing one is never overwritten
  unless ``overwrite`` is true.
* ``topics`` (string list, empty = all stack topics).
* ``compression``: ``none`` or ``zstd`` (MCAP chunk compression).
* ``stats_file``: write message counts, CPU time and rate as JSON here on close ('' = no).
* ``log_time``: ``receive`` (default; wall-clock time of reception, what ``ros2 bag
  record`` writes) or ``sim`` (the newest ``/clock`` time received, so a lockstep bag has
  the simulation's time axis).

Subscriptions are reliable with a deep queue (1000; transient local where the publisher
offers it) so nothing is dropped while the bag is being written. SIGINT/SIGTERM close the
bag cleanly (``run_node`` lets the current callback finish, drains what is queued, then
calls :meth:`RecorderNode.close`).
"""

from __future__ import annotations

import struct
import sys
import time
from pathlib import Path

from rabbit_msgs_py import strict_json
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock

from rabbit_msgs_py import qos
from rabbit_msgs_py import topics as topic_names
from rabbit_msgs_py.catalog import STACK_TOPICS, TopicSpec
from rabbit_msgs_py.conversions import stamp_to_ns
from rabbit_msgs_py.parameters import Param, declare
from rabbit_msgs_py.node_runner import NodeStartError, destroyed_if_start_fails, run_node

from .bag import COMPRESSIONS, BagError, BagWriter, QosSpec

LOG_TIMES = ("receive", "sim")
RECORD_DEPTH = 1000
RESENT_TOPICS = (topic_names.JOINT_STATES, topic_names.HIP_VELOCITY, topic_names.CLOCK)
"""Topics sim_node sends again (same stamp) while it waits: written once per stamp."""


class ResendFilter:
    """True for a stamp equal to the previous one on the topic: a state sent again (a
    lockstep re-send, a held start), not a new one. A reset starts again at t = 0, after a
    later stamp, so it is new."""

    def __init__(self) -> None:
        self.last: tuple[int, int] | None = None

    def seen(self, stamp: tuple[int, int]) -> bool:
        repeated = stamp == self.last
        self.last = stamp
        return repeated


def header_stamp(data: bytes) -> tuple[int, int]:
    """(sec, nanosec) of a serialized message that starts with a std_msgs/Header (or, like
    rosgraph_msgs/Clock, with a builtin_interfaces/Time), read from the CDR bytes without
    deserialising (4-byte encapsulation, then the stamp)."""
    return struct.unpack_from("<iI" if data[1] == 1 else ">iI", data, 4)


def _subscription_qos(spec: TopicSpec) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=RECORD_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=spec.qos.durability,
    )


def recorded_qos(topic: str) -> QosSpec:
    """The QoS a bag records for a topic (relative, or fully qualified in any namespace): its
    publisher's, from the stack's catalogue (reliable, volatile, depth 10 for a topic the
    stack does not know)."""
    matches = [name for name in STACK_TOPICS if topic in (name, f"/{name}") or topic.endswith(f"/{name}")]
    spec = STACK_TOPICS[max(matches, key=len)] if matches else None
    if spec is None:
        return QosSpec(True, False, 10)
    return QosSpec(reliable=spec.qos.reliability == ReliabilityPolicy.RELIABLE,
                   transient_local=spec.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL,
                   depth=spec.qos.depth)


RECORDER_PARAMS = {
    "output": Param("", "bag directory to create (required)"),
    "topics": Param([""], "topics to record, relative to the node's namespace or fully qualified ([''] = every "
                          "stack topic)"),
    "compression": Param("none", "none or zstd (MCAP chunk compression)", choices=COMPRESSIONS),
    "log_time": Param("receive", "message log time: receive (wall clock) or sim (/clock)", choices=LOG_TIMES),
    "overwrite": Param(False, "replace an existing bag directory (never anything else)"),
    "stats_file": Param("", "write the recording statistics as JSON here when closing ('' = don't)"),
}


class RecorderNode(Node):
    """Bag recorder. ``counts`` holds messages written per topic."""

    # after a stop signal run_node spins on until nothing new was written for 0.3 s (at most
    # this long), so queued messages are written however loaded the machine is
    drain_on_exit = 10.0

    def activity(self) -> int:
        """Messages handled so far (written, or skipped as sent again): run_node's drain. Once
        stopping, new states written only: a simulator holding for this recorder sends its
        state again, and the controller its reply, every 50 ms, but no new one."""
        if self.stopping:
            return self.bag.counts.get(self.resolve_topic_name(topic_names.JOINT_STATES), 0)
        return sum(self.bag.counts.values()) + self.resends_skipped

    def begin_stop(self) -> None:
        """A stop signal came (run_node, before it drains): report no more progress, so a
        lockstep simulator that follows this recorder holds within a few states of what is
        written, and the drain writes what was received and ends."""
        self.stopping = True

    @destroyed_if_start_fails
    def __init__(self, context=None, namespace: str | None = None, **overrides) -> None:
        super().__init__("recorder_node", context=context, namespace=namespace)
        values = declare(self, RECORDER_PARAMS, overrides)
        value = values.__getitem__
        output = value("output")
        # stack topics by their names in this namespace (the bag's names) and relative
        resolved = {topic_names.resolve(name, self.get_namespace()): name for name in STACK_TOPICS}
        wanted = [t for t in value("topics") if t] or list(STACK_TOPICS)
        names = [resolved.get(t, t) for t in wanted]
        unknown = [t for t, name in zip(wanted, names) if name not in STACK_TOPICS]
        try:
            if not output:
                raise ValueError("parameter 'output' (the bag directory) is required")
            if unknown:
                raise ValueError(f"unknown topics {unknown}; known: {sorted(resolved)}")
            self.bag = BagWriter(output, value("compression"), bool(value("overwrite")))
        except (ValueError, BagError) as exc:
            raise NodeStartError(f"recorder_node: {exc}") from exc
        self.sim_log_time = value("log_time") == "sim"
        self.stats_file = value("stats_file")
        self._start_wall = time.perf_counter()
        self._start_cpu = time.process_time()
        self._sim_now = 0
        self.error: str | None = None
        self.done = False  # run_node stops spinning when true
        self.resends_skipped = 0  # states a simulator sent again, written once
        # the sim time of the newest state written: a lockstep simulator steps only while it
        # is a few states behind, run_stack stops the nodes only once it reaches the run's
        # last state (transient local: the latest value reaches late joiners too)
        self._until = Clock()
        self._until_pub = self.create_publisher(Clock, topic_names.RECORDED_UNTIL, qos.STATUS_QOS)
        self.stopping = False
        # announce this recorder before subscribing (a negative stamp: nothing written yet): a
        # lockstep simulator that runs already holds for it from then on, so it loses nothing
        self._until.clock.sec = -1
        self._until_pub.publish(self._until)
        self._torque_sub = None  # recorded torque replies: no progress is reported before it matched
        for name in names:
            spec = STACK_TOPICS[name]
            self.bag.add_topic(self.resolve_topic_name(name), spec.type_name, recorded_qos(name))
            sub = self.create_subscription(
                spec.msg_class, name, self._writer_for(name), _subscription_qos(spec), raw=True
            )
            if name == topic_names.JOINT_TORQUES:
                self._torque_sub = sub
        self.get_logger().info(f"recording {len(names)} topics to {self.bag.path}")

    @property
    def counts(self) -> dict[str, int]:
        return self.bag.counts

    def _writer_for(self, name: str):
        """The writer of stack topic ``name`` (relative) into the bag, under its full name."""
        topic = self.resolve_topic_name(name)
        is_clock = name == topic_names.CLOCK
        is_state = name == topic_names.JOINT_STATES
        resent = ResendFilter() if name in RESENT_TOPICS else None

        def write(data: bytes) -> None:
            if self.error is not None:
                return
            if resent is not None and resent.seen(header_stamp(data)):
                self.resends_skipped += 1
                if is_state:
                    self._report(data)  # tell a simulator re-sending it again
                return
            if is_clock and self.sim_log_time:
                clock = deserialize_message(data, Clock).clock
                self._sim_now = stamp_to_ns(clock)
            stamp = self._sim_now if self.sim_log_time else time.time_ns()
            try:
                self.bag.write(topic, stamp, data)
            except BagError as exc:
                self.error = str(exc)
                self.done = True  # the process ends (exit status 1): a stack waiting for it learns at once
                self.get_logger().error(f"recording stopped: {exc}")
                return
            if is_state:  # tell a lockstep simulator how far the recording is
                self._report(data)

        return write

    def _report(self, state: bytes) -> None:
        """Publish the stamp of the state just written (or seen again) on
        ``/recorder/recorded_until`` — once the torque replies' subscription has matched a
        controller, if they are recorded: a lockstep simulator holds its first state (sending
        it again, and the controller its reply) until then, so no reply is lost to discovery."""
        if self.stopping:
            return
        if self._torque_sub is not None:
            if self._torque_sub.get_publisher_count() == 0:
                return
            self._torque_sub = None  # matched: once is enough (this runs for every state)
        self._until.clock.sec, self._until.clock.nanosec = header_stamp(state)
        self._until_pub.publish(self._until)

    @property
    def failed(self) -> bool:
        """True once writing or finishing the bag failed (the process then exits with 1)."""
        return self.error is not None

    def close(self) -> None:
        """Finish the bag (MCAP summary, metadata.yaml); a failure is kept in ``error``. Safe
        to call twice."""
        if self.bag.closed:
            return
        try:
            self.bag.close()
        except BagError as exc:
            self.error = self.error or str(exc)
            self.get_logger().error(str(exc))
            self._write_stats()
            return
        total = sum(self.bag.counts.values())
        self.get_logger().info(f"bag {self.bag.path} closed: {total} messages"
                               + (f", but recording stopped early: {self.error}" if self.error else ""))
        self._write_stats()

    def _write_stats(self) -> None:
        total = sum(self.bag.counts.values())
        if self.stats_file:
            wall = time.perf_counter() - self._start_wall
            cpu = time.process_time() - self._start_cpu
            stats = {"messages": total, "counts": self.bag.counts, "resends_skipped": self.resends_skipped,
                     "wall_s": wall, "cpu_s": cpu, "cpu_share": cpu / wall if wall > 0 else None, "error": self.error}
            Path(self.stats_file).write_text(strict_json.dumps(stats) + "\n")


def main(args: list[str] | None = None) -> int:
    """Console script / ``ros2 run rabbit_sim recorder_node``."""
    return run_node(RecorderNode, args)


if __name__ == "__main__":
    sys.exit(main())
