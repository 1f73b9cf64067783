"""Who calls a service (needs rclpy): rclpy hands a service callback the request only, not the
client's DDS id, so a node that must say who reset or paused it names the nodes holding a
client of that service in the ROS graph at the call (the caller is among them, as is any node
that keeps such a client open, e.g. rqt). A ``ros2 service call`` shows as a node whose name starts with ``_ros2cli``."""

from __future__ import annotations

import time
from typing import Callable

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

LOOKUP_EVERY = 1.0
"""s (wall): at most one line, and one read of the graph, this often per service (a flood of
calls costs no graph walk per call); the calls in between are counted in the next line."""


def service_clients(node, service: str) -> list[str]:
    """Full names of the nodes other than ``node`` that hold a client of ``service`` now, sorted."""
    full = node.resolve_service_name(service)
    me = (node.get_name(), node.get_namespace())
    found = []
    for name, namespace in node.get_node_names_and_namespaces():
        if (name, namespace) == me:
            continue
        try:
            clients = node.get_client_names_and_types_by_node(name, namespace)
        except _rclpy.NodeNameNonExistentError:  # it left while the graph was read
            continue
        if any(client == full for client, _types in clients):
            found.append(f"{namespace.rstrip('/')}/{name}")
    return sorted(found)


class CallerLog:
    """Logs the calls of a service on ``node`` with when (sim s) and by whom
    (:func:`service_clients`): at most one line a second per service, which counts the calls
    since the last one. ``clock``: wall s."""

    def __init__(self, node, clock: Callable[[], float] = time.monotonic) -> None:
        self._node, self._clock = node, clock
        self._said: dict[str, float] = {}  # service -> wall s of its last line
        self._unsaid: dict[str, int] = {}  # service -> calls since then not in a line

    def __call__(self, service: str, what: str, sim_time: float) -> None:
        now = self._clock()
        if now - self._said.get(service, -LOOKUP_EVERY) < LOOKUP_EVERY:
            self._unsaid[service] = self._unsaid.get(service, 0) + 1
            return
        names = service_clients(self._node, service)
        self._said[service] = now
        more = self._unsaid.pop(service, 0)
        full = self._node.resolve_service_name(service)
        who = ", ".join(names) if names else "none in the graph yet (a caller that came and went at once)"
        self._node.get_logger().info(f"{full} called ({what}) at t = {sim_time:.3f} s; nodes with a client of it: {who}"
                                     + (f" ({more} more calls since the last line)" if more else ""))
