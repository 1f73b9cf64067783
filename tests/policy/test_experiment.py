"""The one closed loop (rabbit_policy.experiment): scenarios, stop rules, pushes, model
options, torque delay, and the result's one mean-speed definition."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rabbit_msgs_py.decision_ticks import PER_STEP

from rabbit_policy.experiment.loop import ClosedLoop, walk
from rabbit_policy.experiment.result import json_number
from rabbit_policy.experiment.scenario import PhasePush, Push, Scenario
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import LibraryPolicy
from rabbit_sim.physics.model import ModelOptions, load_model
from rabbit_sim.physics.simulation import FallLimits, Simulator, StopRules

pytestmark = pytest.mark.sim

LIBRARY = GaitLibrary.load()
CLASSIC = LibraryPolicy(LIBRARY)


# ------------------------------------------------------------------ unit
@pytest.mark.parametrize("kwargs, message", [
    ({"schedule": ((1.0, 1.0),)}, "start at t = 0"),
    ({"schedule": ((0.0, 1.0), (0.0, 1.2))}, "increase"),
    ({"schedule": ((0.0, math.nan),)}, "finite"),
    ({"torque_delay": -0.001}, "torque_delay"),
    ({"window": 0}, "window"),
])
def test_scenario_rejects_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Scenario(**kwargs)


@pytest.mark.parametrize("kwargs", [{"variant": "moon"}, {"friction": 0.0}, {"friction": math.inf},
                                    {"torso_mass_scale": -1.0}])
def test_model_options_reject_bad_values(kwargs):
    with pytest.raises(ValueError):
        ModelOptions(**kwargs)


def test_stop_rules():
    rules = StopRules(stall_after=2.0)
    assert not rules.stalled(3.9, 2.0) and rules.stalled(4.01, 2.0)
    with pytest.raises(ValueError):
        StopRules(stall_after=0.0)
    assert json_number(math.nan) is None and json_number(math.inf) is None and json_number(1.5) == 1.5


# ------------------------------------------------------------------ model
@pytest.mark.sim
def test_model_options_change_the_compiled_model():
    paper = load_model()
    changed = load_model(ModelOptions(friction=0.4, torso_mass_scale=1.15))
    torso = paper.body("torso").id
    assert changed.geom("left_foot").friction[0] == pytest.approx(0.4)
    assert changed.geom("right_foot").friction[0] == pytest.approx(0.4)
    assert paper.geom("left_foot").friction[0] == pytest.approx(0.8)
    assert changed.body_mass[torso] == pytest.approx(1.15 * paper.body_mass[torso])
    np.testing.assert_allclose(changed.body_inertia[torso], 1.15 * paper.body_inertia[torso])
    drives = load_model(ModelOptions("drives"))
    assert drives.dof_armature[3] == pytest.approx(0.83, abs=0.01)


@pytest.mark.sim
def test_a_slippery_floor_changes_the_walk():
    fine = walk(CLASSIC, Scenario.constant(1.0), 4.0)
    icy = walk(CLASSIC, Scenario.constant(1.0, model=ModelOptions(friction=0.05)), 4.0)
    assert not fine.failed
    assert icy.failed or abs(icy.mean_speed(2.0) - fine.mean_speed(2.0)) > 0.01


# ------------------------------------------------------------------ the loop
@pytest.mark.sim
def test_the_inlined_fall_check_is_the_fall_limits_rule():
    """The loop inlines FallLimits.fallen on its hot path: both say the same thing."""
    limits = FallLimits()
    result = walk(CLASSIC, Scenario.constant(1.0, pushes=(Push(1.0, -400.0, 0.2),)), 4.0, record_state=True)
    assert result.fell
    fallen = [limits.fallen(q[1], q[2]) for q in result.qpos]
    assert fallen[-1] and not any(fallen[:-1])  # the walk ends on the first fallen tick
    assert result.fall_time == pytest.approx(result.times[-1])


@pytest.mark.sim
def test_a_scheduled_push_acts_from_its_time_for_its_duration():
    model = load_model()
    sim = Simulator(model)
    loop = ClosedLoop(Scenario.constant(1.0), CLASSIC)
    sim = loop.sim
    sim.schedule_pushes([Push(0.0105, 50.0, 0.003)])
    seen = []
    loop.observer = lambda lp, _t: seen.append((round(lp.time, 6), lp.sim.push_wrench[0]))
    loop.run(max_ticks=20)
    pushed = [t for t, fx in seen if fx]
    assert pushed == [0.011, 0.012, 0.013]  # due at 10.5 ms: applied after the step that reaches 11 ms, 3 steps


@pytest.mark.parametrize("kwargs, message", [
    ({"after": -1.0}, "after"), ({"phase": 1.0}, "phase"), ({"phase": -0.1}, "phase"),
    ({"force_x": math.nan}, "force_x"), ({"duration": 0.0}, "duration"),
])
def test_a_phase_push_rejects_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        PhasePush(**{"after": 1.0, "phase": 0.5, "force_x": -50.0, "duration": 0.1, **kwargs})


@pytest.mark.sim
def test_a_phase_push_lands_at_its_phase_of_the_first_step_after_its_time():
    phases = (0.25, 0.75)
    pushes = tuple(PhasePush(2.0 + 2.0 * k, phase, -60.0, 0.1) for k, phase in enumerate(phases))
    seen = []
    loop = ClosedLoop(Scenario.constant(1.0, phase_pushes=pushes), CLASSIC,
                      observer=lambda lp, _t: seen.append((lp.time, lp.sim.push_wrench[0])))
    loop.run(7.0)
    touchdowns = [loop.start_time] + [td.time for td in loop.touchdowns]
    assert len(loop.placed_pushes) == 2
    for push, placed, phase in zip(pushes, loop.placed_pushes, phases):
        k = next(i for i, t in enumerate(touchdowns) if i and t >= push.after - 1e-9)  # the step it lands in
        start, previous = touchdowns[k], touchdowns[k] - touchdowns[k - 1]
        assert placed.time == pytest.approx(start + phase * previous)
        assert start < placed.time < touchdowns[k + 1]  # inside that step
        acting = [t for t, fx in seen if fx == -60.0 and placed.time - 1e-9 <= t <= placed.time + 0.2]
        assert len(acting) == 100  # 0.1 s of 1 ms ticks, from its time
    assert loop.sim.pushes_started == 2


@pytest.mark.sim
def test_the_roll_back_rule_declares_a_certain_stall_early_and_leaves_walks_alone():
    """The training env's early failure rule: a backward push classic HZD stalls on is
    declared a stall once the hip has rolled back behind its stance foot for 0.2 s, long
    before the 2 s without a touchdown; an undisturbed walk is the same walk with the rule."""
    early = StopRules(roll_back_after=0.2)
    pushed = (Push(2.0, -150.0, 0.1),)
    late = walk(CLASSIC, Scenario.constant(0.7, pushes=pushed), 8.0)
    soon = walk(CLASSIC, Scenario.constant(0.7, pushes=pushed, rules=early), 8.0)
    assert late.stalled and soon.stalled and not soon.fell
    assert soon.stall_time < late.stall_time - 1.0
    plain = walk(CLASSIC, Scenario.constant(1.0), 5.0)
    ruled = walk(CLASSIC, Scenario.constant(1.0, rules=early), 5.0)
    assert not ruled.failed and np.array_equal(plain.hip_x, ruled.hip_x)
    with pytest.raises(ValueError, match="roll_back_after"):
        StopRules(roll_back_after=-1.0)


@pytest.mark.sim
def test_stall_ends_the_walk_and_is_reported():
    # a strong backward push stops the classic gait at 0.7 m/s upright or throws it over
    result = walk(CLASSIC, Scenario.constant(0.7, pushes=(Push(2.0, -150.0, 0.1),)), 8.0)
    assert result.failed
    if result.stalled:
        assert result.stall_time == pytest.approx(result.touchdowns[-1].time + 2.0, abs=2e-3)
        assert result.end_time == pytest.approx(result.stall_time)


@pytest.mark.sim
def test_a_torque_delay_applies_each_tick_s_torques_that_much_later():
    import copy

    delayed = ClosedLoop(Scenario.constant(1.0, torque_delay=0.005), CLASSIC)

    def next_torques(lp: ClosedLoop) -> list[float]:
        """What the controller computes on the next tick (a copy of it, on this state)."""
        return copy.deepcopy(lp.controller).compute(lp.data.qpos, lp.data.qvel)

    computed, applied = [next_torques(delayed)], []

    def observe(lp: ClosedLoop, torques) -> None:
        applied.append(list(torques))
        computed.append(next_torques(lp))

    delayed.observer = observe
    delayed.run(max_ticks=40)
    assert applied[:5] == [computed[0]] * 5  # the first torques, held over the 5 ms
    assert applied[5:] == computed[:35]  # then each tick's torques, 5 ticks later
    assert computed[10] != computed[0]
    # measured: the classic gaits walk with up to 3 ms of delay, some fail at 4-5 ms
    result = walk(CLASSIC, Scenario.constant(1.0, torque_delay=0.002), 10.0)
    assert not result.failed


@pytest.mark.sim
def test_mean_speed_is_displacement_over_time_and_matches_the_hip_speed_samples():
    result = walk(CLASSIC, Scenario(schedule=((0.0, 0.9), (3.0, 1.2))), 9.0)
    assert result.mean_speed(1.0, 3.0) == pytest.approx(
        (result.hip_x[2999] - result.hip_x[999]) / (result.times[2999] - result.times[999]))
    mask = (result.times > 1.0 + 1e-9) & (result.times <= 3.0 + 1e-9)
    assert result.mean_speed(1.0, 3.0) == pytest.approx(result.hip_speed[mask].mean(), abs=1e-9)
    summary = result.summary()
    json.dumps(summary, allow_nan=False)
    assert [s["command"] for s in summary["segments"]] == [0.9, 1.2]
    assert summary["segments"][1]["reach_time"] is not None


def test_a_periodic_policy_decides_every_n_ticks_on_a_one_step_moving_average():
    from rabbit_policy.runtime.policies import PeriodicPolicy
    from rabbit_policy.spec.make import make_policy
    from rabbit_policy.runtime.speed_window import Observation

    seen: list[Observation] = []

    class Spy:
        name = "spy"

        def __init__(self) -> None:
            self.inner = make_policy("classic", decision=PER_STEP)

        def act(self, observation):
            seen.append(observation)
            return self.inner.act(observation)

    policy = PeriodicPolicy(Spy(), 25)
    loop = ClosedLoop(Scenario.constant(1.0), policy)
    seen.clear()  # the starting gait's decision
    loop.run(4.0)
    assert not loop.failed
    assert len(loop.decisions) == len(seen) == 4000 // 25
    # the average spans the last whole step: on the cycle it is the step's mean speed,
    # steady from one decision to the next (the within-step swing averages out)
    late = [o.mean_speed for o in seen[-40:]]
    assert max(late) - min(late) < 0.02
    steps = loop.result().step_speeds()
    assert abs(late[-1] - steps[-1][2]) < 0.03
    with pytest.raises(ValueError):
        PeriodicPolicy(Spy(), 0)


def test_queued_kd_and_alpha_take_effect_at_touchdown():
    from rabbit_policy.experiment.loop import ClosedLoop
    from rabbit_policy.experiment.scenario import Scenario
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.policies import GaitCommand

    lib = GaitLibrary.load()
    slow, fast = lib.nearest(0.8), lib.nearest(1.2)
    loop = ClosedLoop(Scenario.constant(0.8), start=GaitCommand(slow.alpha, slow.kd))
    controller = loop.controller
    assert loop.set_gait(GaitCommand(fast.alpha, fast.kd))
    loop.run(duration=0.3)  # within the first step: still the gait in force
    assert controller.kd == slow.kd and controller.alpha == tuple(slow.alpha)
    assert controller.pending_alpha is not None and controller.pending_kd == fast.kd
    assert not loop.run(duration=2.0, until_touchdown=True) and loop.touchdowns
    assert controller.kd == fast.kd and controller.alpha == tuple(fast.alpha)
    assert controller.pending_kd is None and controller.pending_alpha is None


@pytest.mark.sim
@pytest.mark.parametrize("controller", ["classic", "learned", "recovery"])
def test_the_compiled_runs_of_ticks_are_the_loop_ticked_one_at_a_time(controller):
    """ClosedLoop.run hands runs of ticks to the compiled inner loop and decides between them
    (rabbit_policy.experiment.ticks); ticked one at a time (the observer's path) it must walk
    the same to the last bit: decisions, touchdowns, a phase push, a command change between
    two decisions, a torque delay, a stall by time included."""
    from rabbit_policy.spec.make import make_policy

    scenario = Scenario(schedule=((0.0, 0.8), (1.2345, 1.3)), pushes=(Push(2.0, -90.0, 0.1),),
                        phase_pushes=(PhasePush(3.0, 0.4, 120.0, 0.1),), torque_delay=0.001)
    runs = []
    for chunked in (True, False):
        loop = ClosedLoop(scenario, make_policy(controller))
        if chunked:
            loop.run(5.0, stop_on_fall=False)
        else:
            for _ in range(5000):
                loop.tick()
        runs.append(loop)
    a, b = runs
    assert a.ticks == b.ticks == 5000
    assert np.array_equal(a.data.qpos, b.data.qpos) and np.array_equal(a.data.qvel, b.data.qvel)
    assert a.touchdowns == b.touchdowns and a.decisions == b.decisions and a.placed_pushes == b.placed_pushes
    assert a.result().times.tolist() == b.result().times.tolist() and a.peak_torque == b.peak_torque
    assert (a.fell, a.stalled, a.fall_time, a.stall_time) == (b.fell, b.stalled, b.fall_time, b.stall_time)
    assert len(a.decisions) > 10 and len(a.touchdowns) >= 2


@pytest.mark.sim
def test_a_stall_by_time_is_dated_at_the_same_tick_whether_the_ticks_run_compiled_or_one_by_one():
    scenario = Scenario.constant(0.7, pushes=(Push(2.0, -150.0, 0.1),))
    chunked = ClosedLoop(scenario, CLASSIC)
    chunked.run(8.0)
    single = ClosedLoop(scenario, CLASSIC)
    while not single.tick():
        pass
    assert chunked.failed and (chunked.stall_time, chunked.fall_time) == (single.stall_time, single.fall_time)
    assert chunked.ticks == single.ticks
