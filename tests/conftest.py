"""Test-session environment and tiers.

Every ROS process in the tests discovers on localhost only
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST unless set) and uses a domain ID of its own, so
concurrent runs do not cross-talk.

Tiers (markers, declared in pytest.ini): each test module has a kind — ``unit`` (no
simulation, no ROS), ``sim`` (real MuJoCo walks, no ROS) or ``ros`` (real rclpy nodes or
node processes) — unless a test marks itself. ``slow``: a test over about 0.7 s on a slow
2-core machine (raw mj_step ~110k steps/s) marks itself ``@pytest.mark.slow`` where it is
defined (older ones are still listed in :data:`SLOW`); ``make test-fast`` leaves them out
and runs in about 20 s there.
"""

import os
import random

import pytest

from rabbit_msgs_py.environment import ensure_localhost_discovery

ensure_localhost_discovery()
os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 101)))

KIND = {
    "test_bezier_alpha": "unit", "test_phase_kinematics": "unit", "test_poincare": "unit",
    "test_manifests": "unit", "test_stepping": "unit", "test_policy_parts": "unit",
    "test_msgs_conversions": "unit", "test_parameters": "ros",
    "test_controller": "sim", "test_model": "sim", "test_walking": "sim", "test_experiment": "sim",
    "test_env": "sim", "test_gait_optimization": "sim", "test_evaluation": "sim", "test_training": "sim",
    "test_stack_nodes": "ros", "test_recording": "ros", "test_run_stack_script": "ros",
    "test_ros_install": "ros", "test_colcon_install": "ros", "test_parallel": "sim", "test_visualization": "ros", "test_play": "ros",
}

SLOW = {
    "tests/test_training.py::test_train_es_logs_checkpoints_and_resumes_exactly",
    "tests/test_training.py::test_train_ppo_logs_its_losses_and_refuses_a_foreign_resume",
    "tests/test_training.py::test_train_stops_cleanly_on_ctrl_c_or_sigterm",
    "tests/test_evaluation.py::test_evaluate_quick_writes_report_results_figures_and_videos",
    "tests/test_evaluation.py::test_ros_stack_push_outcome_matches_the_fast_path",
    "tests/test_env.py::test_warm_started_network_reproduces_the_library_and_walks",
    "tests/test_stack_nodes.py::test_controller_restart_mid_walk_lockstep_waits_and_resumes",
    "tests/test_stack_nodes.py::test_realtime_watchdog_damps_while_the_controller_is_gone",
    "tests/test_stack_nodes.py::test_stack_walks_and_cmd_speed_changes_the_speed",
    "tests/test_recording.py",
    "tests/test_play.py",
    "tests/test_visualization.py::test_sim_node_viewer_leaves_the_lockstep_run_unchanged",
    "tests/test_visualization.py::test_walk_viewer_leaves_results_unchanged_and_needs_a_display",
    "tests/test_run_stack_script.py",
    "tests/test_colcon_install.py",
    "tests/test_parallel.py::test_es_on_the_local_backend_is_the_same_for_one_or_two_workers",
    "tests/test_parallel.py::test_ppo_iteration_on_ray_actors_equals_local",
    "tests/test_parallel.py::test_an_evaluation_sweep_is_the_same_on_ray_and_local",
    "tests/test_parallel.py::test_a_worker_killed_mid_generation_is_rerun_not_lost",
    "tests/test_parallel.py::test_a_node_lost_mid_generation_has_its_tasks_rerun",
    "tests/test_parallel.py::test_es_on_a_two_node_ray_cluster_equals_local",
}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if not any(item.get_closest_marker(kind) for kind in ("unit", "sim", "ros")):
            kind = KIND.get(item.path.stem)
            if kind is None:
                raise pytest.UsageError(f"{item.path.name}: give the module a kind in tests/conftest.py KIND")
            item.add_marker(getattr(pytest.mark, kind))
        test_id = item.nodeid.split("[")[0]
        if test_id in SLOW or test_id.split("::")[0] in SLOW:
            item.add_marker(pytest.mark.slow)
