"""Is another rabbit-hzd stack running in this namespace of this ROS domain? (Two would cross-talk.)"""

from __future__ import annotations

import time
from typing import Callable

from rabbit_msgs_py import topics
from rabbit_msgs_py.node_runner import init_context


class AnotherStack(RuntimeError):
    """Another stack runs in this namespace: ``found`` says what of it was seen."""

    def __init__(self, found: list[str]) -> None:
        super().__init__(", ".join(found))
        self.found = found


STACK_NODE_NAMES = ("sim_node", "hzd_controller_node", "policy_node", "run_stack_supervisor")
"""The nodes that make a stack: a simulator, a controller or a policy of ours, or another run_stack.
A recorder alone, a bag being replayed or any other publisher of our topics is not a stack."""


def other_stack(wait: float = 3.0, namespace: str = "", stop: Callable[[], bool] = lambda: False) -> list[str]:
    """Nodes of another rabbit-hzd stack visible in ``namespace`` ("" = the root) of this ROS
    domain (after ``wait`` s of discovery; found ones end the wait early; 1.5 s missed a
    running stack once on a loaded machine): a node named as one of ours
    (:data:`STACK_NODE_NAMES`), or a simulator's release service there; empty if none. Two
    stacks in one namespace cross-talk (one's cmd_speed moves the other), so a launch refuses
    to start beside one; stacks in other namespaces do not count, nor does a lone publisher of
    our topics (a test tool, ``play.py`` replaying a bag). ``stop()`` true (Ctrl-C) ends the
    wait early with what was found."""
    import rclpy

    context = init_context()
    full = namespace or "/"
    try:
        node = rclpy.create_node("run_stack_probe", context=context, namespace=full)
        deadline = time.monotonic() + wait
        found: list[str] = []
        while time.monotonic() < deadline and not found and not stop():
            time.sleep(0.1)
            found = sorted({name for name, ns in node.get_node_names_and_namespaces()
                            if name in STACK_NODE_NAMES and ns == full})
            service = node.resolve_service_name(topics.RELEASE_CONTROLLER_SERVICE)
            if any(name == service for name, _types in node.get_service_names_and_types()):
                found.append(f"a simulator's {service} service")
        node.destroy_node()
        return found
    finally:
        rclpy.shutdown(context=context)
