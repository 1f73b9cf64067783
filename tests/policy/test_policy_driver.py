"""``PolicyDriver``, policy_node's ROS-free core: the node's rules run without a node (events
in, actions out), as SimDriver's and ControllerDriver's do."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from rabbit_policy.policy_driver import Gait, Log, PolicyDriver, PolicySettings, Scheduled
from rabbit_policy.spec.make import make_policy

pytestmark = pytest.mark.sim

MS = 1_000_000  # ns per tick


def driver(policy: str = "classic", schedule: str = "", **settings) -> PolicyDriver:
    values = dict(min_speed=0.7, max_speed=1.5, initial_speed=1.0, window=1000, decision_window=1000,
                  speed_schedule=schedule)
    return PolicyDriver(make_policy(policy), PolicySettings(**{**values, **settings}))


def test_the_core_imports_no_ros():
    code = "import sys, rabbit_policy.policy_driver; print(any(m.startswith('rclpy') for m in sys.modules))"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout == "False\n"


def test_start_then_a_decision_every_20_ticks_on_the_mean_hip_speed():
    core = driver()
    first = core.start()
    assert len(first) == 1 and isinstance(first[0], Gait) and first[0].initial_state is not None
    gaits = [a for tick in range(1, 61) for a in core.on_hip_velocity(tick * MS, 1.0) if isinstance(a, Gait)]
    assert len(gaits) == 3 and core.decisions == 4
    assert core.last_observation.desired_speed == 1.0


def test_bad_commands_are_rejected_with_one_line_and_the_last_good_one_stays():
    core = driver()
    assert core.on_command(1.2, "/cmd_speed") == [Log("info", "commanded speed 1.20 m/s")]
    rejected = core.on_command(float("nan"), "/cmd_speed")
    assert core.desired_speed == 1.2 and core.rejected_commands == 1
    assert [a.level for a in rejected] == ["error"] and "keeping 1.20 m/s" in rejected[0].text
    assert core.on_command(float("inf"), "/cmd_speed") == []  # the same kind within a second: counted, said later
    assert core.rejected_commands == 2
    clamped = core.on_command(9.0, "/cmd_speed")
    assert core.desired_speed == 1.5 and clamped[0].level == "warning"
    with pytest.raises(ValueError, match="must not be above"):
        core.set_range(1.3, 1.0)
    core.set_range(0.8, 1.1)
    assert core.desired_speed == 1.1  # the command in force clamped into the new range


def test_a_scheduled_change_is_commanded_published_once_and_its_echo_ignored():
    core = driver(schedule="0.105:1.3")
    actions = [a for tick in range(1, 108) for a in core.on_hip_velocity(tick * MS, 1.0)]
    assert [a for a in actions if isinstance(a, Scheduled)] == [Scheduled(1.3)] and core.desired_speed == 1.3
    assert core.on_cmd_speed(1.3, "/cmd_speed") == [] and core.rejected_commands == 0  # our own, heard back
    core.on_cmd_speed(1.0, "/cmd_speed")
    assert core.desired_speed == 1.0
    core.on_placed(1)
    core.on_placed(2)  # a reset: the schedule starts over from the start's command
    assert core.desired_speed == 1.0 and [a for tick in range(1, 108) for a in core.on_hip_velocity(tick * MS, 1.0)
                                          if isinstance(a, Scheduled)] == [Scheduled(1.3)]


def test_a_body_state_decision_waits_for_its_phase_and_is_given_up_with_a_line():
    core = driver("learned")
    assert core.needs_body and core.decision_period == 20
    core.start()
    actions = []
    for tick in range(1, 100):  # states but never a phase from the controller
        actions += core.on_hip_velocity(tick * MS, 1.0)
        actions += core.on_body_state(tick * MS, np.zeros(7), np.zeros(7))
    given_up = [a for a in actions if isinstance(a, Log) and a.level == "error"]
    assert core.decisions_given_up >= 1 and given_up and "/hzd/phase" in given_up[0].text
    assert not [a for a in actions if isinstance(a, Gait)]  # the gait in force stays


@pytest.mark.parametrize("settings, word", [({"min_speed": 1.2, "max_speed": 1.0}, "min_speed"),
                                            ({"window": 0}, "window"), ({"decision_window": -1}, "decision_window"),
                                            ({"speed_schedule": "2:1.2,2.05:1.3"}, "speed_schedule")])
def test_settings_it_cannot_run_with_are_one_line(settings, word):
    with pytest.raises(ValueError, match=word):
        driver(**settings)


def test_the_decision_window_is_the_spec_s_unless_the_node_is_given_one(tmp_path):
    """The ROS path honours the spec's ``decision.window_ticks`` as walk.py does (the node's
    ``decision_window`` 0, the default); a window given to the node (> 0) overrides it."""
    import yaml

    from rabbit_policy.spec import packaged_spec

    data = yaml.safe_load(packaged_spec("recovery").read_text())
    data["decision"]["window_ticks"] = 300
    edited = tmp_path / "recovery.yaml"
    edited.write_text(yaml.safe_dump(data, sort_keys=False))
    policy = make_policy("recovery", policy_file=edited)
    values = dict(min_speed=0.7, max_speed=1.5, initial_speed=1.0, window=1000, speed_schedule="")
    for given, window in ((0, 300), (500, 500)):
        core = PolicyDriver(policy, PolicySettings(**values, decision_window=given))
        assert core.clock.window.size == window, (given, window)



def test_the_initial_state_is_computed_and_sent_only_when_the_gait_changed():
    """Classic at a constant command decides the same gait every 20 ticks: its initial state
    (the simulator's start and reset state) is computed once and not sent again; a new gait
    carries its own."""
    from rabbit_hzd_controller.gait_state import state_on_gait

    core = driver()
    (first,) = core.start()
    assert not first.same_initial_state
    gaits = [a for tick in range(1, 41) for a in core.on_hip_velocity(tick * MS, 1.0) if isinstance(a, Gait)]
    assert len(gaits) == 2 and all(g.same_initial_state and g.command.alpha == first.command.alpha for g in gaits)
    assert all(g.initial_state is first.initial_state for g in gaits)
    core.on_cmd_speed(1.3, "/cmd_speed")
    changed = [a for tick in range(41, 81) for a in core.on_hip_velocity(tick * MS, 1.0) if isinstance(a, Gait)]
    assert changed[0].command.alpha != first.command.alpha and not changed[0].same_initial_state
    expected = state_on_gait(changed[0].command.alpha, 1.0)
    assert all(np.array_equal(a, b) for a, b in zip(changed[0].initial_state, expected))


def test_a_command_flood_moves_the_command_no_faster_than_its_rate():
    """/cmd_speed at 1 kHz cycling nan, inf, -5 and 1e9 (issue 75): the bad ones are refused, the
    clamped ones (0.7 and 1.5 m/s) are followed at command_rate, so the command the policy walks
    drifts by at most 2 mm/s a tick instead of jumping 0.8 m/s every ms."""
    core = driver(command_rate=2.0)
    core.start()
    core.on_hip_velocity(MS, 1.0)
    commands, flood = [], [float("nan"), float("inf"), -5.0, 1e9]
    for tick in range(2, 2002):
        core.on_cmd_speed(flood[tick % 4], "/cmd_speed")
        core.on_hip_velocity(tick * MS, 1.0)
        commands.append(core.desired_speed)
    steps = np.abs(np.diff([1.0] + commands))
    assert steps.max() <= 2.0e-3 + 1e-12 and 0.7 <= min(commands) and max(commands) <= 1.5
    assert core.rejected_commands == 1000
    core.on_cmd_speed(1.3, "/cmd_speed")  # one command: reached in (1.3 - v) / 2 s, then held
    for tick in range(2002, 3002):
        core.on_hip_velocity(tick * MS, 1.0)
    assert core.desired_speed == 1.3 and core.target is None


def test_the_schedule_applies_at_once_whatever_the_command_rate():
    core = driver(schedule="0.2:1.4", command_rate=2.0)
    core.start()
    for tick in range(1, 202):
        core.on_hip_velocity(tick * MS, 1.0)
    assert core.desired_speed == 1.4


def test_a_simulation_that_stops_is_named_once_after_a_second_of_wall_time_and_its_return_is_said():
    """The policy's view of a killed simulator (or a lockstep simulation no controller answers):
    its samples stop. The driver's timer names it once SIM_SILENT_WALL wall s have passed, not
    before any sample, and says when the samples come again."""
    from rabbit_policy.policy_driver import SIM_SILENT_WALL

    core = driver()
    core.start()
    assert core.check_simulation(0.0) == [] and core.check_simulation(100.0) == []  # no sample yet: not started
    for tick in range(1, 31):
        core.on_hip_velocity(tick * MS, 1.0)
    assert core.check_simulation(100.0) == []
    assert core.check_simulation(100.0 + SIM_SILENT_WALL) == []
    (warning,) = core.check_simulation(100.0 + SIM_SILENT_WALL + 0.01)
    assert warning.level == "warning" and "the simulation is silent" in warning.text and "t = 0.030 s" in warning.text
    assert core.check_simulation(200.0) == [] and core.simulation_silences == 1  # said once
    core.on_hip_velocity(31 * MS, 1.0)
    (back,) = core.check_simulation(200.5)
    assert back.level == "info" and "back" in back.text
