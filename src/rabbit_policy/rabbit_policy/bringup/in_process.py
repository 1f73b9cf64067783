"""A run with every node in this process, on one executor."""

from __future__ import annotations

import os
import time
from typing import Sequence

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py.node_runner import freeze_start_up_objects, init_context, make_executor, spin_timeout_of
from rabbit_policy.policy_node import PolicyNode
from rabbit_sim.recorder_node import RecorderNode
from rabbit_sim.sim_node import SimNode

from .config import StackConfig
from .cpu import CpuMeter
from .supervisor import RunReport, Supervisor, spin_until_done, wait_for_recording


def run_in_process(config: StackConfig, stall_timeout: float = 30.0, executor_kind: str | None = None,
                   observers: Sequence[object] = (), stop=lambda: False,
                   policy: object | None = None) -> tuple[RunReport, dict[str, object]]:
    """Run the stack in this process on one executor; returns the report and the nodes
    (for tests and benchmarks). ``observers``: extra node factories ``f(context)``;
    ``stop()``: polled, true ends the run early (the caller's signal handling); ``policy``:
    ``config.build_policy()`` if the caller built it already (policy_node takes it, not
    building it again)."""
    import rclpy

    context = init_context()
    nodes: dict[str, object] = {}
    executor = None
    try:
        compose(config, context, tuple(config.node_parameters()), nodes, policy)
        supervisor = nodes["supervisor"] = Supervisor(config, context=context)
        for i, factory in enumerate(observers):
            nodes[f"observer_{i}"] = factory(context)
        executor = make_executor(context, executor_kind)
        for node in nodes.values():
            executor.add_node(node)
        freeze_start_up_objects()
        spin_timeout = min(spin_timeout_of(node) for node in nodes.values())
        meter = CpuMeter({"run_stack": os.getpid()})
        error = spin_until_done(executor, supervisor, stall_timeout, spin_timeout=spin_timeout, stop=stop,
                                meter=meter)
        error = error or wait_for_recording(executor, supervisor, stall_timeout)
        cpu = meter.per_tick_us(supervisor.sim_stamp)
        drain_until = time.monotonic() + 0.3  # deliver what is in flight (last states, recorder)
        while time.monotonic() < drain_until:
            executor.spin_once(timeout_sec=0.005)
        recorder = nodes.get("recorder_node")
        if recorder is not None:
            recorder.close()  # finish the bag now: a failure to is the run's failure
            if recorder.error and not error:
                error = f"recording failed: {recorder.error}"
        policy, controller = nodes.get("policy_node"), nodes.get("hzd_controller_node")
        report = supervisor.report(error, policy.policy.name if policy is not None else None)
        report.take_controller_counts(controller.statistics() if controller is not None else None)
        report.cpu_us_per_tick = cpu
        return report, nodes
    finally:
        if executor is not None:
            executor.shutdown()  # an executor left alive keeps its wait thread busy
        close_nodes(nodes)
        if context.ok():
            rclpy.shutdown(context=context)


def compose(config: StackConfig, context, names: tuple[str, ...], nodes: dict[str, object],
            policy: object | None = None) -> dict[str, object]:
    """Make the stack's nodes ``names`` (of ``config.node_parameters()``) in this process, in
    ``context``, into ``nodes`` (in the order policy, controller, simulator, recorder), as a
    component container would: each a node of its own, with its name, parameters and
    topics. ``policy``: the policy already built (policy_node takes it). Returns ``nodes``
    (filled as far as it got when a node fails to start: close them with :func:`close_nodes`)."""
    params = config.node_parameters()
    ns = config.namespace or None
    for name in ("policy_node", "hzd_controller_node", "sim_node", "recorder_node"):
        if name not in names:
            continue
        if name == "policy_node":
            nodes[name] = PolicyNode(context=context, namespace=ns, built_policy=policy, **params[name])
        elif name == "hzd_controller_node":
            nodes[name] = HZDControllerNode(context=context, namespace=ns, **params[name])
        elif name == "sim_node":
            nodes[name] = SimNode(context=context, namespace=ns, **params[name])
        else:
            nodes[name] = RecorderNode(context=context, namespace=ns, **params[name])
    return nodes


def close_nodes(nodes: dict[str, object]) -> None:
    """Close (statistics files, a bag) and destroy each node, in order."""
    for node in nodes.values():
        close = getattr(node, "close", None)
        if close:
            close()
        node.destroy_node()
