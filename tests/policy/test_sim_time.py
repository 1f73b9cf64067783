"""Every node works with ``use_sim_time:=true``, namespaced, in every mode: nothing a node
needs before the simulator starts waits on sim time (which stands still until the
simulator runs). Started so, the nodes once stayed in their solo check for good, and a
paced simulator logged "simulation running" and published nothing."""

from __future__ import annotations

import pytest

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_policy.bringup.config import StackConfig
from rabbit_policy.bringup.supervisor import Supervisor, spin_until_done
from rabbit_policy.policy_node import PolicyNode
from rabbit_sim.sim_node import SimNode

from ros_helpers import ros_context

pytestmark = [pytest.mark.ros, pytest.mark.slow]


@pytest.mark.parametrize("mode", ["lockstep", "paced", "realtime"])
def test_the_nodes_walk_with_use_sim_time_namespaced_in_every_mode(mode):
    config = StackConfig(duration=1.5, schedule=((0.0, 1.0),), mode=mode, rtf=2.0, namespace="/simtime")
    params = config.node_parameters()
    # as an engineer sets it on every node of a namespaced stack: sim time, and /clock remapped to its own
    args = ["--ros-args", "-p", "use_sim_time:=true", "-r", f"/clock:={config.namespace}/clock"]
    with ros_context(args=args) as (context, executor):
        nodes = [PolicyNode(context=context, namespace=config.namespace, **{**params["policy_node"], "solo_check": 0.3}),
                 HZDControllerNode(context=context, namespace=config.namespace,
                                   **{**params["hzd_controller_node"], "solo_check": 0.3}),
                 SimNode(context=context, namespace=config.namespace, **{**params["sim_node"], "solo_check": 0.3})]
        supervisor = Supervisor(config, context=context)
        for node in (*nodes, supervisor):
            executor.add_node(node)
        assert all(node.get_parameter("use_sim_time").value for node in nodes)
        error = spin_until_done(executor, supervisor, stall_timeout=30.0)
        sim = nodes[2]
        if mode == "realtime":  # a busy machine may halt a realtime run at any time: it must have run, and
            # either finished or halted for falling behind the wall clock (the one error realtime allows)
            assert sim.sim.time > 0.0 and (error is None or "realtime mode halts" in error), error
            return
        assert error is None and supervisor.report(None, None).completed, error
        assert sim.sim.time >= 1.5 - 1e-9
        # the nodes' clocks follow /clock (the simulator's own)
        assert 1.0 <= nodes[0].get_clock().now().nanoseconds * 1e-9 <= 1.5 + 1e-9
