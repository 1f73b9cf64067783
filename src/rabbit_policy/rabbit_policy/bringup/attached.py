"""A run on a stack that is not this run's: nodes started by hand (``ros2 run``), watched and
commanded from this process (``run_stack.py --attach``). Nothing is started or stopped; the
supervisor sends the schedule on ``/cmd_speed`` from the first state it sees, and the report
reads the stack's controller (which policy, its lost decisions) off the graph."""

from __future__ import annotations

import time
from dataclasses import replace

import rclpy
from rclpy.parameter_client import AsyncParameterClient

from rabbit_msgs_py.node_runner import init_context, make_executor
from rabbit_msgs_py.pairing import user_key, user_key_file
from rabbit_policy.runtime.policies import PolicyUnavailable
from rabbit_policy.spec.make import spec_kind

from .config import StackConfig, policy_name
from .probe import STACK_NODE_NAMES
from .supervisor import RunReport, Supervisor, spin_until_done

PARAMETER_WAIT = 5.0
"""s (wall): how long the policy node's parameters are waited for."""
DISCOVERY_WAIT = 5.0
"""s (wall): how long the stack's nodes are looked for (discovery on a busy machine)."""


class NothingToAttach(RuntimeError):
    """No stack started by hand runs here (or one that a run_stack supervises): the one line says which."""


def stack_nodes(node, wait: float = DISCOVERY_WAIT) -> list[str]:
    """The stack nodes (:data:`~.probe.STACK_NODE_NAMES`) in ``node``'s namespace, looked for
    until a simulator, a controller and a policy are all seen or ``wait`` s have passed."""
    deadline = time.monotonic() + wait
    while True:
        names = [name for name, ns in node.get_node_names_and_namespaces()
                 if name in STACK_NODE_NAMES and ns == node.get_namespace()]
        if node.get_name() in names:  # this one (another run_stack's supervisor has the same name)
            names.remove(node.get_name())
        found = sorted(set(names))
        if all(name in found for name in STACK_NODE_NAMES[:3]) or time.monotonic() > deadline:
            return found
        time.sleep(0.1)


def attachable(found: list[str], namespace: str) -> None:
    """Raise :class:`NothingToAttach` unless ``found`` (:func:`stack_nodes`) holds a
    simulator, a controller and a policy, and no run_stack supervisor (two supervisors would
    both command the robot)."""
    where = f"namespace {namespace or '/'}"
    if "run_stack_supervisor" in found:
        raise NothingToAttach(f"the stack in {where} is a run_stack's (it sends its own commands): --attach watches "
                              "a stack started by hand")
    missing = [name for name in STACK_NODE_NAMES[:3] if name not in found]
    if missing:
        raise NothingToAttach(f"no stack to attach to in {where}: {', '.join(missing)} not found (start sim_node, "
                              "hzd_controller_node and policy_node with ros2 run: docs/ros2-cli.md)")


def stack_policy(node, executor, timeout: float = PARAMETER_WAIT) -> tuple[str, str]:
    """(controller, its file) the stack's policy_node runs, from its parameters: ``spec_file``'s
    kind, else ``policy`` with ``policy_file``; ``("", "")`` if it does not answer within
    ``timeout`` s."""
    client = AsyncParameterClient(node, "policy_node")
    if not client.wait_for_services(timeout_sec=timeout):
        return "", ""
    future = client.get_parameters(["policy", "policy_file", "spec_file"])
    rclpy.spin_until_future_complete(node, future, executor=executor, timeout_sec=timeout)
    if not future.done() or future.result() is None:
        return "", ""
    policy, policy_file, spec_file = (value.string_value for value in future.result().values)
    if spec_file:
        try:
            return spec_kind(spec_file), spec_file
        except PolicyUnavailable:  # (a file this process cannot read: the node's own kind stands)
            return policy, spec_file
    return policy, policy_file


def run_attached(config: StackConfig, stall_timeout: float = 30.0,
                 stop=lambda: False) -> tuple[RunReport, StackConfig]:
    """Attach to the stack running in ``config.namespace`` (:func:`attachable`, else
    :class:`NothingToAttach`), send ``config``'s schedule from its first state on, and
    return the report once ``config.duration`` s of its sim time have passed (or it fell,
    stalled or stopped), with the config as run (its controller the stack's). The batches
    are checked with the user's pairing key (the key nodes started by hand pair by); the
    report's controller is the policy node's (:func:`stack_policy`), its lost decisions the
    controller's ``/hzd/decisions_lost`` count since the start."""
    key_path = user_key_file()  # (never made here: without it the stack's nodes run with a key given, or none)
    config = replace(config, pairing_key=user_key(key_path).secret.decode() if key_path.exists() else "",
                     layout="attach")
    context = init_context()
    supervisor = None
    executor = None
    try:
        supervisor = Supervisor(config, context=context)
        attachable(stack_nodes(supervisor), config.namespace)
        executor = make_executor(context)
        executor.add_node(supervisor)
        policy, policy_file = stack_policy(supervisor, executor)
        if policy:
            config = replace(config, controller=policy, policy_file=policy_file)
            supervisor.config = config
        error = spin_until_done(executor, supervisor, stall_timeout, stop=stop)
        report = supervisor.report(error, policy_name(config) if policy else None)
        if not policy:
            report.controller = "unknown (policy_node did not answer its parameters)"
        return report, config
    finally:
        if executor is not None:
            executor.shutdown()
        if supervisor is not None:
            supervisor.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)
