"""hzd_controller_node's log at a start: a state answered before the policy's first gait is
said, not warned about."""

from __future__ import annotations

import pytest
from sensor_msgs.msg import JointState

from rabbit_hzd_controller.hzd_controller_node import HZDControllerNode
from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.conversions import stamp_from_ns
from rabbit_msgs_py.joints import JOINT_NAMES
from rabbit_msgs_py.pairing import resolve_key
from rabbit_sim.physics.model import load_model

from ros_helpers import ros_context, spin_for, spin_until

pytestmark = pytest.mark.ros


def _state(stamp_ns: int) -> JointState:
    """RABBIT as the model places it (keyframe-free: qpos0), at ``stamp_ns``, signed with the
    user's key as a simulator started by hand signs its states (the controller takes no other)."""
    model = load_model("paper")
    q, dq = [float(v) for v in model.qpos0], [0.0] * len(JOINT_NAMES)
    key, _source = resolve_key("")
    msg = JointState(name=list(JOINT_NAMES), position=q, velocity=dq, effort=[0.0] * len(JOINT_NAMES))
    msg.header.stamp = stamp_from_ns(stamp_ns)
    msg.header.frame_id = key.sign_state("state_sender/test", 1, stamp_ns, q, dq)  # (placed once)
    return msg


def _controller_and_state_publisher(context, executor):
    """A controller node and a publisher of /joint_states (the test plays the simulator), spun by ``executor``."""
    import rclpy

    controller = HZDControllerNode(context=context)
    sender = rclpy.create_node("state_sender", context=context)
    for node in (controller, sender):
        executor.add_node(node)
    return controller, sender.create_publisher(JointState, topics.JOINT_STATES, qos.STREAM_QOS)

def test_a_state_before_the_first_gait_is_a_start_not_a_warning(capfd, monkeypatch):
    """Every normal start sends the placed state before the policy's first gait arrives: the
    controller once warned "no gait yet" at each. It says so only once the gait has been
    missing for GAITLESS_WARNING_AFTER s (here made 0 to see the warning come)."""
    from rabbit_hzd_controller import hzd_controller_node
    with ros_context() as (context, executor):
        controller, pub = _controller_and_state_publisher(context, executor)
        state = _state(0)
        pub.publish(state)
        assert spin_until(executor, lambda: controller.states_received >= 1)
        spin_for(executor, 0.1)
        assert "no gait yet" not in capfd.readouterr().err
        monkeypatch.setattr(hzd_controller_node, "GAITLESS_WARNING_AFTER", 0.0)
        pub.publish(_state(1_000_000))
        assert spin_until(executor, lambda: controller.states_received >= 2)
        spin_for(executor, 0.1)
        assert "no gait yet (waiting for /hzd/alpha and /hzd/kd" in capfd.readouterr().err


def test_a_simulator_that_stops_sending_is_named_by_the_controller_within_two_seconds(capfd):
    """The states stop (a hand-started sim_node killed with -9 sends nothing again): the
    controller's warning names the simulator (after SIM_SILENT_WALL s of wall time: the unit
    test times it on a fake clock) and counts the silence in its statistics."""
    with ros_context() as (context, executor):
        controller, pub = _controller_and_state_publisher(context, executor)
        for tick in range(3):
            pub.publish(_state(tick * 1_000_000))
        assert spin_until(executor, lambda: controller.states_received >= 3)
        assert spin_until(executor, lambda: controller.statistics()["simulator_silences"] == 1)
        spin_for(executor, 0.1)
    err = capfd.readouterr().err
    assert "the simulator is silent: no state on the joint states for 1 s" in err and "sim_node stopped" in err
