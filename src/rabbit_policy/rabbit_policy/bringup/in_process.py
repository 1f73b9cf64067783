"""A run with every node in this process, on one executor."""

from __future__ import annotations

import time
from typing import Sequence

from rabbit_msgs_py.runtime import freeze_start_up_objects, init_context, spin_timeout_of

from .config import StackConfig
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

    from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
    from rabbit_msgs_py.runtime import make_executor
    from rabbit_sim.sim_node import SimNode

    from rabbit_policy.policy_node import PolicyNode

    context = init_context()
    nodes: dict[str, object] = {}
    executor = None
    try:
        params = config.node_parameters()
        ns = config.namespace or None
        nodes["policy_node"] = PolicyNode(context=context, namespace=ns, built_policy=policy, **params["policy_node"])
        nodes["hzd_controller_node"] = HZDControllerNode(context=context, namespace=ns, **params["hzd_controller_node"])
        nodes["sim_node"] = SimNode(context=context, namespace=ns, **params["sim_node"])
        if "recorder_node" in params:
            from rabbit_sim.recorder_node import RecorderNode

            nodes["recorder_node"] = RecorderNode(context=context, namespace=ns, **params["recorder_node"])
        supervisor = nodes["supervisor"] = Supervisor(config, context=context)
        for i, factory in enumerate(observers):
            nodes[f"observer_{i}"] = factory(context)
        executor = make_executor(context, executor_kind)
        for node in nodes.values():
            executor.add_node(node)
        freeze_start_up_objects()
        spin_timeout = min(spin_timeout_of(node) for node in nodes.values())
        error = spin_until_done(executor, supervisor, stall_timeout, spin_timeout=spin_timeout, stop=stop)
        error = error or wait_for_recording(executor, supervisor, stall_timeout)
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
        report.rejected = controller.rejected_gaits if controller is not None else None
        return report, nodes
    finally:
        if executor is not None:
            executor.shutdown()  # an executor left alive keeps its wait thread busy
        for node in nodes.values():
            close = getattr(node, "close", None)
            if close:
                close()
            node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)
