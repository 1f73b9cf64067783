"""Is another rabbit-hzd stack running in this namespace of this ROS domain? (Two would cross-talk.)"""

from __future__ import annotations

import time
from typing import Callable

from rabbit_msgs_py import topics
from rabbit_msgs_py.runtime import init_context


class AnotherStack(RuntimeError):
    """Another stack runs in this namespace: ``found`` says what of it was seen."""

    def __init__(self, found: list[str]) -> None:
        super().__init__(", ".join(found))
        self.found = found


STACK_NODE_NAMES = ("sim_node", "hzd_controller_node", "policy_node", "recorder_node", "run_stack_supervisor")


def other_stack(wait: float = 3.0, namespace: str = "", stop: Callable[[], bool] = lambda: False) -> list[str]:
    """Nodes of another rabbit-hzd stack visible in ``namespace`` ("" = the root) of this ROS
    domain (after ``wait`` s of discovery; found ones end the wait early; 1.5 s missed a
    running stack once on a loaded machine), or publishers of its topics there; empty if
    none. Two stacks in one namespace cross-talk (one's cmd_speed moves the other), so a
    launch refuses to start beside one; stacks in other namespaces do not count. ``stop()``
    true (Ctrl-C) ends the wait early with what was found."""
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
            for topic in (topics.JOINT_STATES, topics.JOINT_TORQUES, topics.ALPHA):
                if node.count_publishers(topic):
                    found.append(f"a publisher of {topic}")
        node.destroy_node()
        return found
    finally:
        rclpy.shutdown(context=context)
