"""The recovery controller (rabbit_policy.runtime.recovery): its rule and step memory, that it
is classic HZD when nothing pushes, that it acts on a push, and that the ROS stack runs it as
the ROS-free loop does."""

from __future__ import annotations

import numpy as np
import pytest

from rabbit_msgs_py.decision_ticks import PER_STEP

from rabbit_policy.experiment.loop import ClosedLoop, walk
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.runtime.policies import controller_settings
from rabbit_policy.spec.make import make_policy
from rabbit_policy.runtime.recovery import CONTROLLER_SETTINGS, RecoveryConfig, StepMemory

DEFAULT_SETTINGS = {"within_step_blend": 0.2, "within_step_until": 0.6, "blend_phase": 0.2}
"""The controller's own gait timing (ControllerConfig's), as a spec names it."""


def timing(policy) -> dict:
    """The gait-timing part of the controller settings ``policy`` runs with (its spec's)."""
    settings = controller_settings(policy)
    return {k: settings[k] for k in CONTROLLER_SETTINGS}


@pytest.mark.unit
def test_step_memory_gives_the_slowest_of_the_previous_steps_at_the_phase():
    memory = StepMemory(bins=4, depth=2, max_dropped=2)
    for speeds in ([1.0, 1.1, 1.2, 1.3], [0.9, 1.2, 1.0, 1.4]):  # two whole steps at command 1 m/s
        for b, v in enumerate(speeds):
            assert memory.observe(0.125 + 0.25 * b, v, 1.0) is None  # not two whole steps yet
    assert memory.observe(0.1, 0.5, 1.0) == 0.9  # a touchdown (the phase fell back): min(1.0, 0.9) in bin 0
    assert memory.observe(0.6, 0.5, 1.0) == 1.0  # bin 2: min(1.2, 1.0)
    # each step's hip velocity over the larger of its command and today's
    assert memory.observe(0.6, 0.5, 2.0) == 0.5  # accelerated: min(1.2, 1.0) / 2.0
    assert memory.observe(0.6, 0.5, 0.5) == 1.0  # decelerated: over the steps' own 1.0
    memory.reset()
    assert memory.observe(0.5, 1.0, 1.0) is None
    with pytest.raises(ValueError):
        RecoveryConfig(offsets=(0.1, 0.1))
    with pytest.raises(ValueError):
        RecoveryConfig(bins=1)


@pytest.mark.unit
def test_a_forgotten_step_is_dropped_and_the_steps_before_stay_the_reference():
    memory = StepMemory(bins=4, depth=2, max_dropped=2)
    for _ in range(2):  # two whole steps at the command's pace
        for b in range(4):
            memory.observe(0.125 + 0.25 * b, 1.0, 1.0)
    assert memory.observe(0.1, 0.3, 1.0) == 1.0  # a touchdown; a pushed step begins
    memory.forget()
    for b in range(1, 4):
        memory.observe(0.125 + 0.25 * b, 0.3, 1.0)
    assert memory.observe(0.1, 1.0, 1.0) == 1.0  # kept, this step would be the slowest: 0.3
    memory.forget()  # undone by a reset
    memory.reset()
    for _ in range(3):
        for b in range(4):
            memory.observe(0.125 + 0.25 * b, 0.3 if _ == 2 else 1.0, 1.0)
    assert memory.observe(0.1, 1.0, 1.0) == 0.3  # not forgotten: the slow step is in the memory
    with pytest.raises(ValueError):
        RecoveryConfig(forget_weight=0.0)


@pytest.mark.unit
def test_the_rule_forgets_a_pushed_step_so_that_it_sees_the_next_push():
    """Three pushes 2 s apart: with the pushed step kept in the memory (the slowest of the
    four), the rule did not act on a second push within four steps (docs/learning.md
    2026-11-28 (second)). Here the rule's weight saturates in one step; that step is left
    out, and the same deficit in the next step is seen again."""
    from rabbit_policy.runtime.speed_window import Observation

    policy = make_policy("recovery")

    def decide(tau: float, hip_velocity: float) -> float:
        policy.act(Observation(1.0, 1.0, 0.0, body=(0.0, 0.0, tau, 2.0, hip_velocity)))
        return policy.last_weight

    taus = [i / 25 for i in range(1, 25)]
    for _ in range(5):
        for tau in taus:
            decide(tau, 1.0)
    pushed = [decide(tau, 0.4) for tau in taus]  # a whole step far behind: w saturates
    assert max(pushed) >= policy.config.forget_weight
    again = [decide(tau, 0.4) for tau in taus]
    assert again[len(taus) // 2] == pytest.approx(pushed[len(taus) // 2])  # the reference is the walk before the push


@pytest.mark.unit
def test_at_most_forget_steps_steps_in_a_row_are_forgotten():
    memory = StepMemory(bins=4, depth=2, max_dropped=2)

    def step(hip_velocity: float, forget: bool = False) -> float | None:
        """One step (4 bins; the phase falling back starts the next); the reference at its end."""
        for b in range(4):
            reference = memory.observe(0.125 + 0.25 * b, hip_velocity, 1.0)
            if forget:
                memory.forget()
        return reference

    references = [step(1.0), step(1.0), step(0.3, True), step(0.3, True), step(0.3, True), step(1.0)]
    assert references[2:5] == [1.0, 1.0, 1.0]  # two slow steps dropped; the reference stays the walk before
    assert references[5] == pytest.approx(0.3)  # the third slow step in a row is kept
    with pytest.raises(ValueError):
        RecoveryConfig(forget_steps=-1)
    with pytest.raises(ValueError):
        RecoveryConfig(forget_after=float("nan"))


@pytest.mark.unit
def test_nothing_is_forgotten_within_forget_after_of_a_change_of_the_command():
    """After a change of the command the hip lags the new one step after step (accelerating
    from the slow end, the rule catches a stall at full weight); those steps are kept, so the
    memory follows the walk. A walk's start is not a change."""
    from rabbit_policy.runtime.speed_window import Observation

    def run(change: bool) -> list[float]:
        policy = make_policy("recovery").with_config(RecoveryConfig(forget_after=4.0))
        taus = [i / 25 for i in range(1, 25)]  # a step of 24 decisions (0.48 s)
        for _ in range(5):
            for tau in taus:
                policy.act(Observation(1.0, 1.0, 0.0, body=(0.0, 0.0, tau, 2.0, 1.0)))
        command = 1.02 if change else 1.0  # a small step up, ramped within one decision
        weights = []
        for _ in range(2):  # two slow steps at the new command
            for tau in taus:
                policy.act(Observation(command, 1.0, 0.0, body=(0.0, 0.0, tau, 2.0, 0.4)))
                weights.append(policy.last_weight)
        return weights

    steady, changed = run(False), run(True)
    assert max(steady[:24]) >= 0.9 and max(changed[:24]) >= 0.9  # the first slow step: full weight either way
    assert steady[36] > 0.9  # forgotten: the second slow step is measured against the walk before
    assert changed[36] == 0.0  # kept: the second is measured against the first


@pytest.mark.unit
def test_the_rule_acts_only_inside_the_step_and_only_when_the_hip_falls_behind():
    policy = make_policy("recovery")
    assert policy.weight(0.3, 1.0, None) == 0.0  # no reference yet
    assert policy.weight(0.3, 1.0, 1.0) == 0.0  # as fast as the steps before
    assert policy.weight(0.3, 1.5, 1.0) == 0.0  # faster (a forward push): classic
    assert policy.weight(0.3, 0.0, 1.0) == 1.0  # far behind: saturated
    assert 0.0 < policy.weight(0.3, 0.8, 1.0) < 1.0
    assert policy.weight(0.0, 0.0, 1.0) == 0.0 and policy.weight(1.0, 0.0, 1.0) == 0.0  # phase clamped


@pytest.mark.unit
def test_last_weight_is_the_rules_weight_at_the_last_decision():
    """``last_weight`` (what a gated residual and the diagnostics read): 0 on a steady walk,
    > 0 once the hip falls behind the previous steps at the same phase, 0 again after a reset."""
    from rabbit_policy.runtime.speed_window import Observation

    policy = make_policy("recovery")
    assert policy.last_weight == 0.0

    def decide(tau: float, hip_velocity: float) -> float:
        policy.act(Observation(1.0, 1.0, 0.0, body=(0.0, 0.0, tau, 2.0, hip_velocity)))
        return policy.last_weight

    taus = [i / 25 for i in range(1, 25)]
    steady = [decide(tau, 1.0) for _ in range(5) for tau in taus]  # five steps at the command's pace (the memory holds four)
    assert steady == [0.0] * len(steady)
    assert decide(0.5, 0.3) > 0.0  # far behind the previous steps at this phase
    policy.reset()
    assert policy.last_weight == 0.0


@pytest.mark.unit
def test_the_rule_watches_an_acceleration_and_holds_off_only_while_the_command_ramps_down():
    """Accelerating, the hip is as fast as in the steps before: no push. If it then falls
    far behind them while the base gait still ramps up (the stall an acceleration from 0.7
    m/s to 1.3 m/s ran into, the ramp held short of the command), the rule acts. Until
    2026-11-27 it held off during every ramp and those walks fell. Ramping down, it holds off."""
    from rabbit_policy.runtime.speed_window import Observation

    policy = make_policy("recovery")
    taus = [i / 25 for i in range(1, 25)]

    def decide(command: float, tau: float, hip_velocity: float) -> float:
        policy.act(Observation(command, 0.7, 0.0, body=(0.0, 0.0, tau, 2.0, hip_velocity)))
        return policy.last_weight

    assert [decide(0.7, tau, 0.7) for _ in range(5) for tau in taus] == [0.0] * 120  # steady at 0.7 m/s
    early = [decide(1.3, tau, 0.75) for tau in taus[:8]]  # the command jumps; the hip speeds up
    assert early == [0.0] * 8 and 0.7 < policy._base.command < 1.3  # still ramping, held from 0.2 of phase
    assert decide(1.3, 0.4, 0.1) == 1.0  # the hip stops while the base gait ramps up: act
    policy.reset()
    [decide(1.3, tau, 1.3) for _ in range(5) for tau in taus]  # steady at 1.3 m/s
    assert decide(0.7, 0.04, 1.3) == 0.0 and decide(0.7, 0.4, 0.1) == 0.0  # commanded down: not a push


@pytest.mark.sim
def test_an_acceleration_from_0_7_to_1_3_m_s_at_a_touchdown_walks():
    """The ordered change that fell at every phase until the rule watched accelerations
    (checks 1-6, docs/learning.md 2026-11-27 (fourth)): 0.7 -> 1.3 m/s at the touchdown
    after 6 s; the hip slows to about 0.1 m/s in the first stance after it. It walks, and
    speeds up (slowly: about 1.15 m/s 5 s later)."""
    from rabbit_policy.evaluation.robustness import phase_times

    policy = make_policy("recovery")
    change = phase_times(policy, 0.7, 6.0, [0.0])[0]
    result = walk(policy, Scenario(schedule=((0.0, 0.7), (change, 1.3))), change + 6.0)
    assert not result.failed
    assert result.step_speeds()[-1][2] > 1.0


@pytest.mark.unit
def test_make_policy_gives_the_recovery_controller_and_the_settings_it_needs():
    policy = make_policy("recovery")
    assert policy.needs_body and policy.decision_period == 20
    assert timing(policy) == CONTROLLER_SETTINGS
    # classic's spec writes down the controller's gait timing (its defaults when it was written)
    assert timing(make_policy("classic")) == DEFAULT_SETTINGS
    with pytest.raises(ValueError, match="decision period"):
        make_policy("recovery", decision=PER_STEP)
    with pytest.raises(ValueError, match="speed integral"):
        make_policy("recovery", speed_integral=0.2)


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


@pytest.mark.ros
@pytest.mark.slow
def test_lockstep_runs_the_recovery_controller_as_the_ros_free_loop():
    """Through a push that makes the rule act: policy_node builds the body state, the
    controller node (started plain) takes the at-once settings the policy announces, and every
    state is the ROS-free loop's."""
    from rabbit_policy.bringup.config import StackConfig
    from stack_helpers import loop_states

    pushes = (Push(1.2, -90.0, 0.1),)
    reference = loop_states(2.5, policy=make_policy("recovery"), scenario=Scenario.constant(1.0, pushes=pushes))
    config = StackConfig(duration=2.5, schedule=((0.0, 1.0),), controller="recovery", pushes=pushes)
    assert "within_step_blend" not in config.node_parameters()["hzd_controller_node"]
    nodes = assert_lockstep_is(config, reference)
    assert nodes["hzd_controller_node"].config.within_step_blend == 0.0


def assert_lockstep_is(config, reference: np.ndarray) -> None:
    """The stack of ``config``, spun in this process in lockstep, publishes every state of
    ``reference`` (the ROS-free loop's) bit for bit, without a fall and with no decision given up."""
    from rabbit_policy.bringup.in_process import run_in_process
    from stack_helpers import state_recorder

    states: list = []
    report, nodes = run_in_process(config, observers=[state_recorder(states)])
    assert report.completed and not report.fell
    unique = np.array([row for i, row in enumerate(states) if i == 0 or row != states[i - 1]])
    assert unique.shape == reference.shape and np.array_equal(unique, reference)
    assert nodes["policy_node"].decisions_given_up == 0
    return nodes


@pytest.mark.sim
@pytest.mark.slow
def test_the_tuning_counts_the_pushes_and_the_offsets_are_what_saves_them():
    """1.0 m/s, 14 N s backward (1.5x classic's margin) at 0.875 of a step: the tuned rule
    survives it; the same controller with zero offsets (classic's ramped gait, at once) does not."""
    from rabbit_policy.gait_design.recovery_tuning import TuningConfig, push_cases, survivals

    policy = make_policy("recovery")
    config = TuningConfig(margins=((1.0, 9.0),), phases=(0.875,), factors=(1.5,))
    cases = push_cases(policy, config)
    assert [impulse for _, _, impulse in cases] == [-14.0]
    assert survivals(policy, cases, config) == 1
    idle = policy.with_config(RecoveryConfig(offsets=(0.0, 0.0, 0.0, 0.0)))
    assert survivals(idle, cases, config) == 0

