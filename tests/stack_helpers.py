"""Helpers for the ROS 2 node stack tests (tests/policy/test_stack_*.py): a stack's nodes
added to an executor, a recorder of /joint_states, the ROS-free loop's states to compare with,
and a learned policy file with a nonzero residual."""

from __future__ import annotations

import numpy as np
from sensor_msgs.msg import JointState

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py import qos, topics
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.policy_node import PolicyNode
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.spec.make import make_policy
from rabbit_sim.sim_node import SimNode

from ros_helpers import spin_until


def state_recorder(store: list):
    """A node factory (for run_in_process's observers): a node that appends each /joint_states
    message's positions and velocities to ``store``."""
    def factory(context):
        import rclpy

        node = rclpy.create_node("trajectory_recorder", context=context)
        node.create_subscription(
            JointState, topics.JOINT_STATES,
            lambda m: store.append(list(m.position) + list(m.velocity)), qos.STREAM_QOS,
        )
        return node
    return factory


def loop_states(duration: float, speed: float = 1.0, policy=None, scenario: Scenario | None = None) -> np.ndarray:
    """Every state of the ROS-free loop (default: classic, every 20 ticks, as policy_node)."""
    loop = ClosedLoop(scenario or Scenario.constant(speed), policy or make_policy("classic"))
    data = loop.data
    rows = [data.qpos.tolist() + data.qvel.tolist()]
    for _ in range(int(round(duration / 0.001))):
        loop.tick()
        rows.append(data.qpos.tolist() + data.qvel.tolist())
    return np.array(rows)


def residual_policy_file(path, features: str = "memory") -> str:
    """A learned policy of the final run's kind, saved as train.py saves one: memory inputs
    (or ``body``: the body state too), a residual on the library at v_d + 0.3 x the speed
    integral, and a small nonzero residual (the last layer perturbed, and for ``body`` the
    weights of the body inputs), so the network's output and those inputs matter."""
    import torch

    from rabbit_policy.learning.warm_start import zero_residual_network
    from rabbit_policy.runtime.actions import RESIDUAL_SCALE, policy_bounds
    from rabbit_policy.runtime.memory import INPUTS, MemoryConfig
    from rabbit_policy.runtime.network import PolicyCheckpoint

    library = GaitLibrary.load()
    bounds = policy_bounds("residual", library)
    net = zero_residual_network(bounds.low, bounds.high, INPUTS[features], seed=5)
    with torch.no_grad():
        net.body[-1].bias.uniform_(-0.05, 0.05, generator=torch.Generator().manual_seed(5))
        if features == "body":  # the last layer reads the hidden units, which read the five body inputs
            net.body[-1].weight.uniform_(-0.02, 0.02, generator=torch.Generator().manual_seed(6))
    PolicyCheckpoint(net.state_dict(), bounds.low, bounds.high,
                     {"features": features, "action": "residual", "residual_scale": list(RESIDUAL_SCALE),
                      "integral_gain": 0.3,
                      "memory": MemoryConfig.for_features(features, 20, 0.3, library.speed_range).to_dict(),
                      "config": {"decision_period": 20}}).save(path)
    return str(path)


def start_stack(context, executor, **sim_params):
    """The three nodes (no key: each its defaults) in ``context``, added to ``executor``."""
    nodes = {
        "policy": PolicyNode(context=context),
        "controller": HZDControllerNode(context=context),
        "sim": SimNode(context=context, **sim_params),
    }
    for node in nodes.values():
        executor.add_node(node)
    return nodes


def call_service(executor, client, request):
    """Call a service and spin until it answers: its response."""
    future = client.call_async(request)
    assert spin_until(executor, future.done)
    return future.result()


def start_sim_and_policy(context, executor, **sim_params):
    """A simulator and a policy (with the simulator's ``pairing_key``, if any) in ``context``,
    added to ``executor``: the controller is the test's."""
    nodes = {"policy": PolicyNode(context=context, pairing_key=sim_params.get("pairing_key", "")),  # the stack's key
             "sim": SimNode(context=context, **sim_params)}
    for node in nodes.values():
        executor.add_node(node)
    return nodes


def context_node(context):
    """A bare node in ``context`` (a publisher of resets, for the test to wire)."""
    import rclpy

    return rclpy.create_node("reset_publisher", context=context)

