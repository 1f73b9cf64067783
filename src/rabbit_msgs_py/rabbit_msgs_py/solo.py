"""One node of each kind per stack (needs rclpy): a simulator, controller or policy started
in a namespace that already has one refuses to start, with one line, before it publishes or
subscribes anything, so the running robot is never disturbed.

Discovery takes time (a node started beside a running stack may see it only after a few
hundred ms, more on a loaded machine), so a node started as a process of its own
(``ros2 run``) looks for ``solo_check`` s (default :data:`PROCESS_SOLO_CHECK`) before it wires
its topics. It refuses if it finds, in its namespace, another node of its name, or one that
offers what only its kind offers (the simulator: ``sim/release_controller``). Any other
publisher of its topics does not count: a rogue (or a test tool) on ``/joint_torques`` must
not keep the real controller from starting, and with a pairing key it cannot move the robot
anyway. run_stack looks for a whole stack itself before it starts any node, so it starts its
nodes with ``solo_check`` 0, as nodes built in-process are by default.
"""

from __future__ import annotations

import time
from typing import Callable

from .timers import wall_timer

PROCESS_SOLO_CHECK = 4.0
"""s (wall): how long a node started as a process looks for another of its kind when it
finds none (it refuses as soon as it finds one). With ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
a new participant may learn of a running one only from that one's periodic announcement
(Fast DDS: every 3 s): 1 s missed a running simulator in one try of three here, 1.5 s a
running stack once on a loaded machine."""
POLL_PERIOD = 0.1
"""s (wall): how often the graph is read meanwhile."""


SOLO_CHECK_HELP = ("wall s to look for another {kind} in this namespace before starting (refused with one line if "
                   f"there is one); {PROCESS_SOLO_CHECK:g} when started as a process (ros2 run), 0 = don't "
                   "(in-process, and run_stack, which looks for a whole stack first), >= 0")
"""The ``solo_check`` parameter's description; ``{kind}``: simulator, controller, policy."""


def others_of_kind(node, service: str | None = None) -> list[str]:
    """Nodes of ``node``'s kind in its namespace: others of its name, and nodes offering
    ``service`` (what only that kind offers; call before ``node`` offers it)."""
    name, namespace = node.get_name(), node.get_namespace()
    same = [n for n, ns in node.get_node_names_and_namespaces() if n == name and ns == namespace]
    found = [f"{namespace.rstrip('/')}/{name}"] if len(same) > 1 else []
    if service is not None:
        full = node.resolve_service_name(service)
        if any(found_name == full for found_name, _types in node.get_service_names_and_types()):
            found.append(f"a node offering {full}")
    return found


class SoloStart:
    """Call ``start()`` on ``node`` once ``wait`` s passed with no other node of its kind in
    its namespace (at once if ``wait`` is 0); if one turns up first, log one error line and
    mark the node ``failed`` and ``done`` (its process exits 1) without starting it.
    ``kind``: what the node is, for the line ("simulator"); ``service``: what only a node
    of that kind offers, if anything (:func:`others_of_kind`)."""

    def __init__(self, node, kind: str, wait: float, start: Callable[[], None], service: str | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.node, self.kind, self.service, self.start, self.clock = node, kind, service, start, clock
        self.started = False
        self.refused: list[str] = []
        if wait <= 0.0:
            self._start()
            return
        self.deadline = clock() + wait
        node.get_logger().info(f"looking for another {kind} in namespace {node.get_namespace()} for {wait:g} s "
                               "before starting (solo_check)")
        self.timer = wall_timer(node, POLL_PERIOD, self._check)

    def _start(self) -> None:
        self.started = True
        self.start()

    def _check(self) -> None:
        found = others_of_kind(self.node, self.service)
        if found:
            self.timer.cancel()
            self.refused = found
            namespace = self.node.get_namespace()
            self.node.get_logger().error(
                f"another {self.kind} runs in namespace {namespace} ({', '.join(found)}): one per stack; start this "
                "one in another namespace (--ros-args -r __ns:=/rabbit2) or ROS_DOMAIN_ID")
            self.node.failed = True
            self.node.done = True
        elif self.clock() >= self.deadline:
            self.timer.cancel()
            self._start()
