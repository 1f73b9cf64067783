"""The recovery controller (rabbit_policy.runtime.recovery): its rule, its calibration, that it
is classic HZD when nothing pushes, that it acts on a push, and that the ROS stack runs it as
the ROS-free loop does."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rabbit_policy.experiment.loop import ClosedLoop, walk
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.runtime.gait_library import GaitLibrary, packaged_gait_dir
from rabbit_policy.runtime.policies import (PolicyUnavailable, controller_settings, make_policy,
                                            required_controller_settings)
from rabbit_policy.runtime.recovery import CONTROLLER_SETTINGS, HipSpeedProfile, RecoveryConfig


@pytest.mark.unit
def test_profile_interpolates_in_speed_and_phase_and_refuses_bad_tables():
    profile = HipSpeedProfile((1.0, 2.0), ((1.0, 3.0), (2.0, 4.0)))
    assert profile.nominal(1.0, 0.25) == pytest.approx(1.0)  # the first bin's centre
    assert profile.nominal(1.0, 0.5) == pytest.approx(2.0)
    assert profile.nominal(1.5, 0.75) == pytest.approx(3.5)
    assert profile.nominal(9.0, 2.0) == pytest.approx(4.0)  # clamped in speed and phase
    assert HipSpeedProfile.from_dict(profile.to_dict()) == profile
    with pytest.raises(ValueError):
        HipSpeedProfile((2.0, 1.0), ((1.0, 3.0), (2.0, 4.0)))
    with pytest.raises(ValueError):
        HipSpeedProfile((1.0,), ((float("nan"), 1.0),))
    with pytest.raises(ValueError):
        RecoveryConfig(offsets=(0.1, 0.1))


@pytest.mark.unit
def test_the_rule_acts_only_inside_the_step_and_only_when_the_hip_falls_behind():
    policy = make_policy("recovery")
    nominal = policy.profile.nominal(1.0, 0.3)
    assert policy.weight(1.0, 0.3, nominal) == 0.0  # on the profile
    assert policy.weight(1.0, 0.3, nominal + 0.5) == 0.0  # ahead of it (a forward push): classic
    assert policy.weight(1.0, 0.3, nominal - 2.0) == 1.0  # far behind: saturated
    assert policy.weight(1.0, 0.0, 0.0) == 0.0 and policy.weight(1.0, 1.0, 0.0) == 0.0  # phase clamped


@pytest.mark.unit
def test_make_policy_gives_the_recovery_controller_and_the_settings_it_needs(tmp_path):
    policy = make_policy("recovery")
    assert policy.needs_body and policy.decision_period == 20
    assert controller_settings(policy) == CONTROLLER_SETTINGS == required_controller_settings("recovery")
    assert required_controller_settings("classic") == {} and controller_settings(make_policy("classic")) == {}
    with pytest.raises(ValueError, match="decision period"):
        make_policy("recovery", decision_period=0)
    with pytest.raises(ValueError, match="speed integral"):
        make_policy("recovery", speed_integral=0.2)
    for gait in GaitLibrary.load().gaits[:2]:  # a library without a hip speed profile: one line, what to run
        gait.save(tmp_path / f"gait_{gait.speed:.2f}.json")
    with pytest.raises(PolicyUnavailable, match="calibrate_library.py --hip-profile"):
        make_policy("recovery", gait_dir=tmp_path)


@pytest.mark.sim
@pytest.mark.slow
def test_undisturbed_it_walks_exactly_as_classic_hzd():
    for speed in (1.0, 1.3):
        classic = walk(make_policy("classic"), Scenario.constant(speed), 5.0)
        recovery = walk(make_policy("recovery"), Scenario.constant(speed), 5.0)
        assert np.array_equal(classic.hip_x, recovery.hip_x), speed


@pytest.mark.sim
@pytest.mark.slow
def test_it_survives_a_backward_push_classic_hzd_stalls_on():
    """1.0 m/s, -12 N s at 0.875 of a step (classic's binding phase there; its margin is 9 N s)."""
    from rabbit_policy.evaluation.robustness import phase_times

    time = phase_times(make_policy("classic"), 1.0, 3.0, [0.875])[0]
    scenario = Scenario.constant(1.0, pushes=(Push(time, -120.0, 0.1),))
    assert walk(make_policy("classic"), scenario, time + 5.0).failed
    loop = ClosedLoop(scenario, make_policy("recovery"))
    assert loop.controller.config.within_step_blend == 0.0  # the loop runs the settings it needs
    loop.run(time + 5.0)
    assert not loop.failed


@pytest.mark.sim
@pytest.mark.slow
def test_the_packaged_hip_profile_is_what_calibration_measures():
    from rabbit_policy.gait_design.calibration import calibrate_hip_profile

    stored = json.loads((packaged_gait_dir() / "hip_speed_profile.json").read_text())
    fresh = calibrate_hip_profile(GaitLibrary.load()).to_dict()
    assert fresh["speeds"] == stored["speeds"]
    np.testing.assert_allclose(fresh["table"], stored["table"], atol=1e-3)


@pytest.mark.ros
@pytest.mark.slow
def test_lockstep_runs_the_recovery_controller_as_the_ros_free_loop():
    """Through a push that makes the rule act: policy_node builds the body state, run_stack's
    configuration gives the controller node the at-once settings, and every state is the
    ROS-free loop's."""
    from rabbit_policy.bringup.stack import StackConfig, run_in_process
    from test_stack_nodes import _recorder, _reference

    pushes = (Push(1.2, -90.0, 0.1),)
    reference = _reference(2.5, policy=make_policy("recovery"), scenario=Scenario.constant(1.0, pushes=pushes))
    config = StackConfig(duration=2.5, schedule=((0.0, 1.0),), controller="recovery", pushes=pushes)
    assert config.node_parameters()["hzd_controller_node"]["within_step_blend"] == 0.0
    states: list = []
    report, nodes = run_in_process(config, observers=[_recorder(states)])
    assert report.completed and not report.fell
    unique = np.array([row for i, row in enumerate(states) if i == 0 or row != states[i - 1]])
    assert unique.shape == reference.shape and np.array_equal(unique, reference)
    assert nodes["policy_node"].decisions_given_up == 0
