"""``run_stack.py --attach`` (issue 76): a stack started by hand (the real nodes, spun here on
an executor of their own, as three ``ros2 run`` would) watched and commanded by a supervisor
that started none of it; its report counts from its first state, names the stack's policy,
and says when the policy stopped deciding (the controller's ``/hzd/decisions_lost``)."""

from __future__ import annotations

import threading
from contextlib import contextmanager

import pytest

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_policy.bringup.attached import NothingToAttach, attachable, run_attached
from rabbit_policy.bringup.config import StackConfig
from rabbit_policy.commands import run_stack
from rabbit_policy.policy_node import PolicyNode
from rabbit_sim.sim_node import SimNode
from ros_helpers import ros_context, spinning

pytestmark = pytest.mark.ros


@contextmanager
def hand_started(policy: str = "learned", **sim):
    """The three nodes as started by hand (the user's key; the simulator paused at t = 0),
    spun in a thread of their own while the test runs the watcher; yields them by name, and
    their executor."""
    with ros_context() as (context, executor):
        nodes = {"sim_node": SimNode(context=context, start_paused=True, **sim),
                 "hzd_controller_node": HZDControllerNode(context=context),
                 "policy_node": PolicyNode(context=context, policy=policy)}
        for node in nodes.values():
            executor.add_node(node)
        with spinning(executor):
            yield nodes, executor


@pytest.mark.slow
def test_attach_commands_a_stack_started_by_hand_and_reports_it_from_its_first_state():
    with hand_started() as (nodes, _executor):
        report, config = run_attached(StackConfig(duration=6.0, schedule=((0.0, 1.0), (3.0, 1.2))))
        walked = nodes["sim_node"].time
    assert config.controller == "learned" and report.controller == "learned" and report.policy.startswith("learned")
    assert report.completed and not report.fell and report.error is None and report.decisions_lost == 0
    first, second = report.segments
    assert (first["start"], second["start"], second["end"], second["command"]) == (0.0, 3.0, 6.0, 1.2)
    assert second["reach_time"] is not None and abs(second["mean_speed"] - 1.2) < 0.1
    assert report.result.start_time == 0.0 and report.sim_time >= 6.0 and walked >= 6.0


@pytest.mark.slow
def test_attach_says_the_run_is_not_complete_when_the_policy_stops_deciding():
    with hand_started() as (nodes, executor):
        policy = nodes["policy_node"]
        done = threading.Event()

        def lose_the_policy() -> None:  # its decisions stop at t = 1 s of the stack's clock
            while not done.is_set() and nodes["sim_node"].time < 1.0:
                done.wait(0.01)
            executor.remove_node(policy)  # spun no more: it decides nothing from here on

        killer = threading.Thread(target=lose_the_policy, daemon=True)
        killer.start()
        try:
            report, _config = run_attached(StackConfig(duration=3.0, schedule=((0.0, 1.0),)))
        finally:
            done.set()
            killer.join(timeout=10.0)
            policy.destroy_node()
    assert report.decisions_lost and report.decisions_lost > 0
    assert not report.completed and "the policy stopped deciding" in report.error


@pytest.mark.slow
def test_attach_refuses_a_stack_that_a_run_stack_supervises():
    """Another run_stack's supervisor has the name this one has: it is still seen on the graph."""
    from rabbit_policy.bringup.supervisor import Supervisor

    with hand_started() as (nodes, executor):
        other = Supervisor(StackConfig(duration=1.0, schedule=((0.0, 1.0),)), context=nodes["sim_node"].context)
        executor.add_node(other)
        with pytest.raises(NothingToAttach, match="is a run_stack's"):
            run_attached(StackConfig(duration=1.0, schedule=((0.0, 1.0),)))
        executor.remove_node(other)
        other.destroy_node()


def test_attach_refuses_a_graph_without_a_stack_or_with_a_run_stacks():
    with pytest.raises(NothingToAttach, match="policy_node not found"):
        attachable(["hzd_controller_node", "sim_node"], "")
    with pytest.raises(NothingToAttach, match="is a run_stack's"):
        attachable(["hzd_controller_node", "policy_node", "run_stack_supervisor", "sim_node"], "/rabbit2")
    attachable(["hzd_controller_node", "policy_node", "sim_node"], "")


def test_attach_refuses_what_belongs_to_the_stacks_own_nodes(capsys):
    with pytest.raises(SystemExit) as exit_:
        run_stack.main(["--attach", "--push", "1:-40:0.1", "--duration", "2"])
    assert exit_.value.code == 2
    assert "--attach starts no node: --push belong to the stack's own nodes" in capsys.readouterr().err
