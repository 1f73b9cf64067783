"""Helpers for tests that spin the real nodes in the test process."""

from __future__ import annotations

import sys
import time
import weakref
from contextlib import contextmanager
from typing import Callable, Iterator

import rclpy
from rclpy.node import Node

from rabbit_msgs_py.node_runner import make_executor

# Every node the tests create, until destroyed: a node left alive stays in the test worker's
# ROS domain for the rest of the session (nothing collects it in time), and every later
# run_stack there refuses to start beside "another stack". ros_context checks its own.
_LIVE_NODES: "weakref.WeakSet[Node]" = weakref.WeakSet()
_node_init, _node_destroy = Node.__init__, Node.destroy_node


def _tracked_init(self, *args, **kwargs) -> None:
    _node_init(self, *args, **kwargs)
    _LIVE_NODES.add(self)


def _tracked_destroy(self) -> None:
    _LIVE_NODES.discard(self)
    _node_destroy(self)


Node.__init__, Node.destroy_node = _tracked_init, _tracked_destroy


def domain_users(domain_id: int, wait: float = 1.0) -> list[str]:
    """The nodes other processes (or this one) run in ROS domain ``domain_id``, after up to
    ``wait`` s of discovery (found ones end the wait early); empty if none."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        node = rclpy.create_node("test_domain_probe", context=context)
        try:
            deadline = time.monotonic() + wait
            while True:
                found = sorted(f"{ns.rstrip('/')}/{name}" for name, ns in node.get_node_names_and_namespaces()
                               if name != "test_domain_probe")
                if found or time.monotonic() >= deadline:
                    return found
                time.sleep(0.1)
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def free_domain(first: int, stride: int = 1, tries: int = 20, wait: float = 1.0) -> tuple[int, dict[int, list[str]]]:
    """The first ROS domain from ``first`` on (``stride`` apart, within 1-101) where nobody
    runs a node, and the busy ones passed over with their nodes. A session that shared its
    domain with a stack someone else left running (a manual run, another checkout's tests)
    saw extra transient-local messages in its bags and every run_stack refused to start
    "beside another stack"; taking an empty domain at the start avoids that. After ``tries``
    busy domains, the last one tried."""
    skipped: dict[int, list[str]] = {}
    domain = first
    for _ in range(tries):
        users = domain_users(domain, wait)
        if not users:
            break
        skipped[domain] = users
        domain = (domain - 1 + stride) % 101 + 1
    return domain, skipped


def next_domain(domain: int, stride: int, wait: float = 0.3) -> tuple[int, list[str], dict[int, list[str]]]:
    """After a test: ``domain`` again if nobody runs a node in it (``wait`` s of discovery),
    else the next free one ``stride`` apart (the same worker's class, never another's), with
    the nodes found there and the busy domains passed over. A node a test leaves running
    (a stack's process that outlived its test, a killed node still listed) would otherwise
    meet every later test of the worker: a stack that refuses to start "beside another
    stack", a recording with extra messages, a walk that is not the fast path's."""
    users = domain_users(domain, wait)
    if not users:
        return domain, [], {}
    new, busy = free_domain((domain - 1 + stride) % 101 + 1, stride=stride)
    return new, users, busy


@contextmanager
def ros_context(executor_kind: str = "events", domain_id: int | None = None,
                args: list[str] | None = None) -> Iterator[tuple[object, object]]:
    """A fresh rclpy context and executor (in ``domain_id``, default the session's; ``args``:
    the context's command line, e.g. ``["--ros-args", "-p", "use_sim_time:=true"]``); nodes
    added to it are destroyed afterwards. A node of this context the test left alive
    otherwise (taken off the executor, never added) is destroyed too, and the test fails
    saying so (unless it failed already)."""
    context = rclpy.Context()
    rclpy.init(args=args, context=context, domain_id=domain_id)
    executor = make_executor(context, executor_kind)
    left_alive: list[str] = []
    try:
        yield context, executor
    finally:
        try:
            nodes = list(executor.get_nodes())
            # first: an EventsExecutor holds on to what a callback created (a node's topics
            # wired once its solo_check passed), and the node lives on in the domain with it
            executor.shutdown()
            for node in nodes:
                try:
                    close = getattr(node, "close", None)
                    if close:
                        close()
                finally:
                    node.destroy_node()
            for node in [n for n in list(_LIVE_NODES) if n.context is context]:
                left_alive.append(node.get_fully_qualified_name())
                node.destroy_node()
        finally:  # whatever happened above: no node of this test outlives it in the domain
            if context.ok():
                rclpy.shutdown(context=context)
        if left_alive and sys.exc_info()[0] is None:
            raise AssertionError(f"nodes left alive by the test (destroy them, or keep them on the executor): "
                                 f"{', '.join(left_alive)}")


def _executors(executor) -> tuple:
    return tuple(executor) if isinstance(executor, (tuple, list)) else (executor,)


def spin_until(executor, condition: Callable[[], bool], timeout: float = 20.0) -> bool:
    """Spin ``executor`` (or several, in turn: nodes of separate contexts stand in for
    separate processes) until ``condition()`` holds or ``timeout`` wall seconds pass."""
    deadline = time.monotonic() + timeout
    executors = _executors(executor)
    while not condition():
        if time.monotonic() > deadline:
            return False
        for ex in executors:
            ex.spin_once(timeout_sec=0.002 if len(executors) > 1 else 0.01)
    return True


def spin_for(executor, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    executors = _executors(executor)
    while time.monotonic() < deadline:
        for ex in executors:
            ex.spin_once(timeout_sec=0.002 if len(executors) > 1 else 0.01)


@contextmanager
def spinning(executor) -> Iterator[None]:
    """Spin ``executor`` in a background thread for the duration of the block (a node of
    its own context then behaves like a separate process, timing-wise)."""
    import threading

    stop = threading.Event()

    def loop() -> None:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.01)

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(timeout=2.0)


def wait_until(condition: Callable[[], bool], timeout: float = 20.0) -> bool:
    """Poll ``condition()`` (nodes spin elsewhere) until it holds or ``timeout`` passes."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


class GaitSigner:
    """Gaits as a policy started by hand signs them (the user's key, from this test process's
    ``ROS_HOME``): ``alpha(values, kd)`` is the ``/hzd/alpha`` message of the next gait."""

    def __init__(self, source: str = "test_policy/00000000") -> None:
        from rabbit_msgs_py.pairing import resolve_key

        self.key, _ = resolve_key("")
        self.source, self.count = source, 0

    def alpha(self, values, kd: float):
        from rabbit_msgs_py.conversions import alpha_to_msg

        self.count += 1
        return alpha_to_msg(values, self.key.gait_signature(self.source, self.count, list(values), kd))

    def announcement(self, period: int = 0, settings: dict | None = None):
        """The ``/hzd/gait_timing`` message this policy signs (a keyed controller takes none of
        its gaits before it): ``period`` and ``settings`` as ``decision_ticks.gait_timing``."""
        from std_msgs.msg import String

        from rabbit_msgs_py.decision_ticks import gait_timing

        return String(data=self.key.sign_settings(self.source, gait_timing(period, settings)))


class BatchSigner:
    """State batches as a simulator signs them (``key``: a PairingKey; None: the user's, from
    this test process's ``ROS_HOME``, as a sim_node started by hand): ``batch(rows, count)`` is
    the next ``/sim/state_batch`` message."""

    def __init__(self, key=None, source: str = "test_sim/00000000") -> None:
        from rabbit_msgs_py.pairing import resolve_key

        self.key = key if key is not None else resolve_key("")[0]
        self.source, self.count = source, 0

    def batch(self, rows, count: int):
        from rabbit_msgs_py.conversions import state_batch_to_msg

        self.count += 1
        return state_batch_to_msg(rows, count, self.key.batch_label(self.source, self.count, rows.tobytes()))
