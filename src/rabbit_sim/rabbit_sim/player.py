"""Replay a rosbag2 bag on its topics, as ``ros2 bag play`` does (``scripts/play.py``).

Each topic is published with its recorded message type and QoS (reliability and durability
from the bag's ``offered_qos_profiles``; keep-last depth at least :data:`MIN_DEPTH`, so a
fast replay never overwrites a sample a reliable reader has not acknowledged yet), the
serialized bytes as recorded (nothing is deserialised), paced by the bag's log time scaled
by ``rate``. ``clock_rate`` > 0 publishes ``/clock`` from the log time at that rate (the
bag's own ``/clock`` messages are then left out, so one clock runs). Messages of any type
whose Python message package is installed replay; a topic whose type is not installed is
named in one line and skipped.
"""

from __future__ import annotations

import importlib
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from rabbit_msgs_py.node_runner import destroyed_if_start_fails

from .bag import BagError, open_bag

MIN_DEPTH = 1000
"""Keep-last depth of every publisher a replay makes (its topics and its ``/clock``) at least."""
CLOCK_TOPIC = "/clock"


class PlaybackError(BagError):
    """The bag cannot be played (missing, unreadable, no such topic)."""


@dataclass(frozen=True)
class BagTopic:
    """A recorded topic: name, ROS type (``pkg/msg/Type``), QoS it was offered with, count."""

    name: str
    type_name: str
    reliable: bool
    transient_local: bool
    depth: int
    count: int

    def qos(self) -> QoSProfile:
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(self.depth, MIN_DEPTH),
                          reliability=ReliabilityPolicy.RELIABLE if self.reliable else ReliabilityPolicy.BEST_EFFORT,
                          durability=(DurabilityPolicy.TRANSIENT_LOCAL if self.transient_local
                                      else DurabilityPolicy.VOLATILE))


def message_class(type_name: str) -> type:
    """``sensor_msgs/msg/JointState`` -> the installed Python class; ``PlaybackError`` if absent."""
    package, kind, name = (type_name.split("/") + ["", ""])[:3]
    try:
        return getattr(importlib.import_module(f"{package}.{kind}"), name)
    except (ImportError, AttributeError):
        raise PlaybackError(f"message type {type_name} is not installed") from None


def bag_topics(reader) -> list[BagTopic]:
    """The topics of an open ``rosbags`` reader with their recorded QoS (reliable and volatile,
    depth 10, when the bag records none)."""
    topics = []
    for connection in reader.connections:
        profiles = getattr(connection.ext, "offered_qos_profiles", None) or []
        reliable, transient, depth = True, False, 10
        if profiles and not isinstance(profiles, str):
            qos = profiles[0]
            reliable = qos.reliability.name == "RELIABLE"
            transient = qos.durability.name == "TRANSIENT_LOCAL"
            depth = int(qos.depth) or 10
        topics.append(BagTopic(connection.topic, connection.msgtype, reliable, transient, depth,
                               connection.msgcount))
    return topics


def clock_times(start_ns: int, end_ns: int, rate_hz: float) -> Iterator[int]:
    """Log times (ns) at which ``/clock`` is published between the bag's start and end."""
    step = int(round(1e9 / rate_hz))
    t = start_ns
    while t <= end_ns:
        yield t
        t += step


class BagPlayer(Node):
    """Publishes a bag's messages (see the module docstring). :meth:`play` runs one pass."""

    @destroyed_if_start_fails
    def __init__(self, bag: Path, topics: list[str] | None = None, rate: float = 1.0, clock_rate: float = 0.0,
                 context=None, log: Callable[[str], None] = print) -> None:
        super().__init__("rosbag2_player", context=context)
        if not rate > 0.0:
            raise PlaybackError(f"rate must be > 0, got {rate}")
        if clock_rate < 0.0:
            raise PlaybackError(f"clock rate must be >= 0 Hz, got {clock_rate}")
        self.bag, self.rate, self.clock_rate = Path(bag), rate, clock_rate
        reader = open_bag(self.bag)
        try:
            recorded = {t.name: t for t in bag_topics(reader)}
            self.start_ns, self.end_ns = reader.start_time, reader.end_time
        finally:
            reader.close()
        unknown = sorted(set(topics or []) - set(recorded))
        if unknown:
            raise PlaybackError(f"not in {self.bag}: {', '.join(unknown)} (it has {', '.join(sorted(recorded))})")
        chosen = [recorded[name] for name in (topics or sorted(recorded))]
        if clock_rate > 0.0:
            chosen = [t for t in chosen if t.name != CLOCK_TOPIC]  # one clock: ours
        self.topics: dict[str, BagTopic] = {}
        self._topic_pubs = {}
        for topic in chosen:
            try:
                cls = message_class(topic.type_name)
            except PlaybackError as exc:
                log(f"skipping {topic.name}: {exc}")
                continue
            self.topics[topic.name] = topic
            self._topic_pubs[topic.name] = self.create_publisher(cls, topic.name, topic.qos())
        # as deep as the played topics: a burst of clocks (a replay behind its pace on a loaded
        # machine) never overwrites one a reliable reader has not acknowledged yet
        self._clock_pub = (self.create_publisher(Clock, CLOCK_TOPIC, QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=MIN_DEPTH, reliability=ReliabilityPolicy.RELIABLE))
            if clock_rate > 0.0 else None)
        self.published: dict[str, int] = {name: 0 for name in self.topics}
        self.clocks_published = 0

    def play(self, stop: Callable[[], bool] = lambda: False) -> bool:
        """One pass through the bag in log-time order, paced by ``rate``; False if ``stop()``
        became true before the end."""
        reader = open_bag(self.bag)
        try:
            connections = [c for c in reader.connections if c.topic in self.topics]
            clocks = clock_times(self.start_ns, self.end_ns, self.clock_rate) if self._clock_pub else iter(())
            next_clock = next(clocks, None)
            start_wall = time.perf_counter()
            for connection, log_ns, raw in reader.messages(connections=connections):
                while next_clock is not None and next_clock <= log_ns:
                    self._wait_until(start_wall, next_clock, stop)
                    self._publish_clock(next_clock)
                    next_clock = next(clocks, None)
                if not self._wait_until(start_wall, log_ns, stop):
                    return False
                self._topic_pubs[connection.topic].publish(bytes(raw))
                self.published[connection.topic] += 1
            while next_clock is not None:
                if not self._wait_until(start_wall, next_clock, stop):
                    return False
                self._publish_clock(next_clock)
                next_clock = next(clocks, None)
            return True
        finally:
            reader.close()

    def _played_publishers(self) -> list:
        return list(self._topic_pubs.values()) + ([self._clock_pub] if self._clock_pub is not None else [])

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s (wall) until every publisher has a subscriber matched."""
        deadline = time.monotonic() + timeout
        while not all(pub.get_subscription_count() > 0 for pub in self._played_publishers()):
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True

    def wait_for_acknowledgements(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s until every reliable message was acknowledged by every
        subscriber (in its reader's queue: what it does with it is up to it)."""
        from rclpy.duration import Duration

        deadline = time.monotonic() + timeout
        return all(pub.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic())))
                   for pub in self._played_publishers())

    def _publish_clock(self, log_ns: int) -> None:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(log_ns, 1_000_000_000)
        self._clock_pub.publish(msg)
        self.clocks_published += 1

    def _wait_until(self, start_wall: float, log_ns: int, stop: Callable[[], bool]) -> bool:
        """Sleep until the wall time of ``log_ns`` (scaled by the rate); False on ``stop()``."""
        due = start_wall + (log_ns - self.start_ns) * 1e-9 / self.rate
        while True:
            if stop():
                return False
            left = due - time.perf_counter()
            if left <= 0.0:
                return True
            time.sleep(min(left, 0.05))
