"""The test session's ROS isolation: the domain each test process takes is one nobody uses."""

import os

import pytest
import rclpy

from ros_helpers import domain_users, free_domain, next_domain

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_the_session_passes_over_a_domain_someone_already_uses():
    """A node another context runs in a domain (as a stack left running by hand would) makes
    that domain busy: the chooser names the node and moves on, stride apart, within 1-101."""
    ours = int(os.environ["ROS_DOMAIN_ID"])
    busy = (ours - 1 + 50) % 101 + 1  # neither ours nor another worker's (ours +- 1)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=busy)
    try:
        squatter = rclpy.create_node("left_running", context=context, namespace="/someone")
        try:
            assert domain_users(busy, wait=10.0) == ["/someone/left_running"]
            domain, skipped = free_domain(busy, stride=3, tries=1, wait=3.0)
            assert skipped == {busy: ["/someone/left_running"]}
            assert domain == (busy + 2) % 101 + 1 and 1 <= domain <= 101
        finally:
            squatter.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert domain_users(ours, wait=0.5) == []  # this test process's own domain is its alone


def test_after_a_test_that_leaves_a_node_the_worker_moves_to_a_free_domain():
    """next_domain, as the conftest runs it after every ros test: a node left running in the
    domain moves the worker on (stride apart, its own class) and names the node; an empty
    domain is kept."""
    ours = int(os.environ["ROS_DOMAIN_ID"])
    left = (ours - 1 + 40) % 101 + 1  # neither ours nor another worker's
    assert next_domain(left, stride=2, wait=0.3)[:2] == (left, [])
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=left)
    try:
        leak = rclpy.create_node("leaked_stack_node", context=context, namespace="/a_test")
        try:
            assert domain_users(left, wait=10.0) == ["/a_test/leaked_stack_node"]
            new, users, _ = next_domain(left, stride=2, wait=3.0)
            assert users == ["/a_test/leaked_stack_node"]
            assert new in {(left - 1 + 2 * k) % 101 + 1 for k in range(1, 21)}  # stride apart, not left
            assert 1 <= new <= 101 and domain_users(new, wait=0.5) == []
        finally:
            leak.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_a_node_that_started_after_its_solo_check_leaves_the_domain_with_its_test_context():
    """ros_context, as the tests use it: a node that wired its topics from a timer callback
    (a policy started after its solo_check, as one started by hand is) is gone from the
    domain when the block ends, even while the test still holds the node and the executor.
    rclpy's EventsExecutor keeps what a callback created: destroying the node before
    shutting the executor down left it listed, and a later test's run_stack refused to
    start "beside another stack" (CI, 2026-11-27)."""
    from rabbit_policy.policy_node import PolicyNode

    from ros_helpers import ros_context, spin_until

    domain = (int(os.environ["ROS_DOMAIN_ID"]) - 1 + 30) % 101 + 1  # neither ours nor another worker's
    with ros_context(domain_id=domain) as (context, executor):
        policy = PolicyNode(context=context, solo_check=0.3)
        executor.add_node(policy)
        assert spin_until(executor, lambda: policy.solo.started, timeout=20.0)
    assert domain_users(domain, wait=3.0) == []
