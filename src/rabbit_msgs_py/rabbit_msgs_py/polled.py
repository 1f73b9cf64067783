"""A subscription no executor wakes for each message: its messages wait in DDS (up to its
history depth) and its owner takes them in bulk, on a timer and wherever it needs them fresh
(Autoware's "take when needed"). For an observer off the 1 kHz loop of a topic anyone can
flood: the executor that runs the loop then spends nothing per flood message (an rclpy
callback costs about 25 µs a message on the EventsExecutor, a take a few), only the bulk
takes. docs/faults.md measures what a flood costs.

rclpy 7 (Jazzy) has no callback group an executor skips, so the subscription lives on a
reader node of its own that is never spun: ``<owner>_reader`` in the owner's namespace and
context (the same remappings), with no parameter services and no rosout. It shows in
``ros2 node list`` and ``ros2 topic info -v`` as the topic's subscriber.
"""

from __future__ import annotations

from typing import Callable, Iterator

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile


def _never_called(_raw: bytes) -> None:
    """The reader node's callback: it is never spun, so messages are only taken."""


def take_waiting(subscription, raw: bool = True) -> Iterator:
    """Every message waiting in ``subscription``'s reader (its serialized bytes with ``raw``,
    else the message), oldest first, each taken as the iteration reaches it."""
    handle, msg_type = subscription.handle, subscription.msg_type
    while True:
        with handle:
            message = handle.take_message(msg_type, raw)
        if message is None:
            return
        yield message[0]


def subscribe_drained(node: Node, msg_type, topic: str, callback: Callable, qos: QoSProfile, raw: bool = False):
    """``node.create_subscription`` whose callback, after its message, is handed every message
    already waiting in the reader, oldest first (taken as they are handed on: one the callback
    raises on leaves the rest waiting). A burst (a flood) then costs one executor callback
    (about 25 µs on the EventsExecutor), not one a message; a node's own rate of messages is
    taken as before. Returns the subscription."""
    subscription = None

    def on_message(first) -> None:
        callback(first)
        for message in take_waiting(subscription, raw):
            callback(message)

    subscription = node.create_subscription(msg_type, topic, on_message, qos, raw=raw)
    return subscription


class PolledSubscription:
    """``topic``'s messages as serialized bytes, handed to ``callback`` oldest first whenever
    :meth:`take_all` runs: every ``period`` s (wall) on a timer of ``owner``, and whenever the
    owner calls it. ``qos``' depth bounds what waits between takes (older messages are
    dropped past it, as any keep-last reader drops them)."""

    def __init__(self, owner: Node, msg_type, topic: str, qos: QoSProfile, callback: Callable[[bytes], None],
                 period: float) -> None:
        self._reader = rclpy.create_node(f"{owner.get_name()}_reader", namespace=owner.get_namespace(),
                                         context=owner.context, enable_rosout=False, start_parameter_services=False)
        self._subscription = self._reader.create_subscription(msg_type, topic, _never_called, qos, raw=True)
        self._callback = callback
        self.timer = owner.create_timer(period, self.take_all)

    @property
    def topic(self) -> str:
        """The full name of the topic taken."""
        return self._subscription.topic_name

    def take_all(self) -> int:
        """Hand every message waiting to the callback, oldest first; returns how many."""
        taken = 0
        for raw in take_waiting(self._subscription):
            self._callback(raw)
            taken += 1
        return taken

    def destroy(self) -> None:
        """Remove the reader node (the owner destroys its own timer)."""
        self._reader.destroy_node()
