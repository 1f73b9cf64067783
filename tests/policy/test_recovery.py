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


def _overlay(config, period: int = 20):
    """A RecoveryOverlay with the rule's constants as RecoveryConfig's and, for policy_blend,
    the controller's default blend (a spec names both; these tests use the defaults)."""
    from rabbit_hzd_controller.controller import ControllerConfig
    from rabbit_policy.runtime.alpha_blend import AlphaBlend
    from rabbit_policy.runtime.classic import LibraryPolicy
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.recovery import RecoveryOverlay, RecoveryPolicy

    rule = RecoveryPolicy(LibraryPolicy(GaitLibrary.load(), "interpolate"), decision_period=max(period, 1))
    defaults = ControllerConfig()
    blend = (AlphaBlend(defaults.within_step_blend, defaults.within_step_until, period * defaults.tick)
             if config.policy_blend else None)
    return RecoveryOverlay(config, period, rule, blend)


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
    from test_stack_nodes import _reference

    pushes = (Push(1.2, -90.0, 0.1),)
    reference = _reference(2.5, policy=make_policy("recovery"), scenario=Scenario.constant(1.0, pushes=pushes))
    config = StackConfig(duration=2.5, schedule=((0.0, 1.0),), controller="recovery", pushes=pushes)
    assert "within_step_blend" not in config.node_parameters()["hzd_controller_node"]
    nodes = _assert_lockstep_is(config, reference)
    assert nodes["hzd_controller_node"].config.within_step_blend == 0.0


def _assert_lockstep_is(config, reference: np.ndarray) -> None:
    """The stack of ``config``, spun in this process in lockstep, publishes every state of
    ``reference`` (the ROS-free loop's) bit for bit, without a fall and with no decision given up."""
    from rabbit_policy.bringup.in_process import run_in_process
    from test_stack_nodes import _recorder

    states: list = []
    report, nodes = run_in_process(config, observers=[_recorder(states)])
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


def _zero_residual_on_recovery_file(path, base: str = "recovery", scale_weights: float = 0.0) -> None:
    """A checkpoint of the zero residual on the recovery controller, as train.py writes one
    (``scale_weights`` > 0: the last layer's weights set to that x a fixed random draw: a
    residual that is not zero)."""
    import torch

    from rabbit_policy.learning.warm_start import zero_residual_network
    from rabbit_policy.runtime.actions import RESIDUAL_SCALE, policy_bounds
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.memory import INPUTS, MemoryConfig
    from rabbit_policy.runtime.network import PolicyCheckpoint

    library = GaitLibrary.load()
    bounds = policy_bounds("residual", library)
    net = zero_residual_network(bounds.low, bounds.high, INPUTS["body"], seed=1)
    if scale_weights:
        last = [m for m in net.body if isinstance(m, torch.nn.Linear)][-1]
        with torch.no_grad():
            last.weight.copy_(scale_weights * torch.as_tensor(np.random.default_rng(3).standard_normal(
                tuple(last.weight.shape))))
    info = {"features": "body", "action": "residual", "output": "tanh", "residual_scale": list(RESIDUAL_SCALE),
            "integral_gain": 0.0, "residual_base": base, "config": {"decision_period": 20},
            "memory": MemoryConfig.for_features("body", 20, 0.0, library.speed_range).to_dict()}
    PolicyCheckpoint(net.state_dict(), bounds.low, bounds.high, info).save(path)


@pytest.mark.sim
@pytest.mark.slow
def test_a_zero_residual_on_the_recovery_base_is_the_recovery_controller_bit_for_bit(tmp_path):
    """The push-recovery issue's fallback: the learned policy as a residual on the recovery
    controller. Its checkpoint says so, the loops and the stack give the controller the at-once
    settings, and the zero residual walks the recovery controller's very trajectory through a
    push the rule acts on."""
    path = tmp_path / "zero.pt"
    _zero_residual_on_recovery_file(path)
    learned = make_policy("learned", policy_file=path)
    assert learned.needs_body and learned.decision_period == 20
    assert timing(learned) == CONTROLLER_SETTINGS
    scenario = Scenario(schedule=((0.0, 1.0), (2.0, 1.2)), pushes=(Push(3.0, -110.0, 0.1),))
    final = []
    for policy in (learned, make_policy("recovery")):
        loop = ClosedLoop(scenario, policy)
        loop.run(5.0)
        assert not loop.failed
        final.append(loop.data.qpos.copy())
    assert np.array_equal(final[0], final[1])


@pytest.mark.sim
@pytest.mark.slow
def test_a_gated_residual_walks_the_recovery_controller_until_the_hip_falls_behind(tmp_path):
    """The ``recovery_gated`` base: a residual that is not zero walks the recovery controller's
    trajectory to the last bit while the rule's weight is 0 (an undisturbed walk), and acts
    once a push slows the hip (the trajectories part). The same residual on the ungated base
    parts from the start."""
    scenario = Scenario(schedule=((0.0, 1.0),))
    pushed = Scenario(schedule=((0.0, 1.0),), pushes=(Push(3.0, -110.0, 0.1),))
    ends = {}
    for base in ("recovery_gated", "recovery"):
        path = tmp_path / f"{base}.pt"
        _zero_residual_on_recovery_file(path, base, scale_weights=0.3)
        policy = make_policy("learned", policy_file=path)
        assert timing(policy) == CONTROLLER_SETTINGS
        for name, sc in (("walk", scenario), ("pushed", pushed)):
            loop = ClosedLoop(sc, policy)
            loop.run(5.0, stop_on_fall=False)
            ends[base, name] = loop.data.qpos.copy()
    for name, sc in (("walk", scenario), ("pushed", pushed)):
        loop = ClosedLoop(sc, make_policy("recovery"))
        loop.run(5.0, stop_on_fall=False)
        ends["none", name] = loop.data.qpos.copy()
    assert np.array_equal(ends["recovery_gated", "walk"], ends["none", "walk"])
    assert not np.array_equal(ends["recovery_gated", "pushed"], ends["none", "pushed"])
    assert not np.array_equal(ends["recovery", "walk"], ends["none", "walk"])


@pytest.mark.unit
def test_a_residual_base_is_checked_where_it_enters():
    from rabbit_policy.learning.env import EpisodeConfig, RabbitHZDEnv

    with pytest.raises(ValueError, match="needs action residual"):
        EpisodeConfig(residual_base="recovery", decision_period=20)
    with pytest.raises(ValueError, match="decision period"):
        EpisodeConfig(residual_base="recovery", action="residual", decision_period=0)
    with pytest.raises(ValueError, match="residual_base must be one of"):
        RabbitHZDEnv(residual_base="raibert", action="residual", decision_period=20)
    env = RabbitHZDEnv(residual_base="recovery", action="residual", decision_period=20, max_steps=20)
    env.reset(seed=0)
    assert env.loop.controller.config.within_step_blend == 0.0  # the base's controller settings


# ------------------------------------------------------------------ the rule as an overlay on another policy
@pytest.mark.unit
def test_an_overlay_configuration_is_checked_where_it_enters():
    from rabbit_policy.runtime.recovery import OverlayConfig, RecoveryOverlay

    for bad in ({"fast_gate": -0.1}, {"fast_gate": float("nan")}, {"hold": 0.0}, {"hold": 1.5}):
        with pytest.raises(ValueError, match="OverlayConfig"):
            OverlayConfig(**bad)
    with pytest.raises(ValueError, match="within the step"):
        _overlay(OverlayConfig(), period=0)
    with pytest.raises(ValueError, match="policy_blend needs the blend"):
        RecoveryOverlay(OverlayConfig(at_once=True, policy_blend=True), 20, _overlay(OverlayConfig()).rule, None)
    with pytest.raises(ValueError, match="recovery_overlay: .*unexpected keyword argument 'gate'"):
        OverlayConfig.from_dict({"gate": 0.1})
    assert OverlayConfig.from_dict({"at_once": True}).controller_settings == CONTROLLER_SETTINGS
    with pytest.raises(ValueError, match="policy_blend needs at_once"):
        OverlayConfig(policy_blend=True)
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="rise_until"):
            OverlayConfig(rise_until=bad)


@pytest.mark.unit
def test_the_alpha_blend_keeps_alpha_and_its_rate_continuous_when_each_decision_restarts_it():
    """A new gait every 0.03 of phase (every 20 ticks at 1.5/s), each restarting the blend:
    at each restart the blended alpha and its rate per unit of phase are those of the blend
    it replaces (a blend restarted from rest at each decision, the first policy blend, drops
    the rate and came in about 3x slower); the gait held for the period is the blend at the
    period's middle; a gait kept reaches its own alpha within 0.2 of phase."""
    from rabbit_policy.runtime.alpha_blend import AlphaBlend

    rng = np.random.default_rng(3)
    blend = AlphaBlend(0.2, 0.6, 0.02)
    blend.start(rng.uniform(-1.0, 1.0, 24), 5.0)
    for k, tau in enumerate(np.arange(0.05, 0.5, 0.03)):
        before, rate_before = blend.at(tau)
        held, kd = blend.step(tau, 1.5, rng.uniform(-1.0, 1.0, 24), 5.0 + k)
        after, rate_after = blend.at(tau)
        np.testing.assert_allclose(after, before, atol=1e-12)
        np.testing.assert_allclose(rate_after, rate_before, atol=1e-9)
        np.testing.assert_array_equal(held, blend.at(tau + 0.5 * 1.5 * 0.02)[0])
        assert kd == 5.0 + k
        if k > 0:
            assert np.abs(rate_after).max() > 0.1  # a blend in progress: its rate is carried, not dropped
    np.testing.assert_array_equal(blend.at(tau + 0.2)[0], blend.target)  # 0.2 of phase after the last restart


@pytest.mark.unit
def test_the_alpha_blend_queues_a_late_gait_and_its_kd_for_the_touchdown():
    """From 0.6 of phase a new gait (and Kd) waits: the blend in force goes on; at the
    touchdown (the phase falling back) the queued gait blends in from the one it replaced,
    over 0.2 of phase from the step's start, at rest."""
    from rabbit_policy.runtime.alpha_blend import AlphaBlend

    blend = AlphaBlend(0.2, 0.6, 0.02)
    blend.start([0.0] * 24, 5.0)
    first, _ = blend.step(0.3, 2.0, [1.0] * 24, 6.0)
    r = 0.5 * 2.0 * 0.02 / 0.2  # the middle of the period: 0.02 of phase into the blend
    assert first == pytest.approx([r * r * (3.0 - 2.0 * r)] * 24, abs=1e-15)
    assert blend.step(0.5, 2.0, [1.0] * 24, 6.0)[0] == pytest.approx([1.0] * 24, abs=1e-15)  # reached by 0.2 of phase
    late, kd = blend.step(0.7, 2.0, [3.0] * 24, 7.0)
    assert late == pytest.approx([1.0] * 24, abs=1e-15) and kd == 6.0  # queued
    landed, kd = blend.step(0.01, 2.0, [3.0] * 24, 7.0)
    r = (0.01 + 0.02) / 0.2  # the middle of the period after the touchdown
    assert kd == 7.0 and landed == pytest.approx([1.0 + 2.0 * r * r * (3.0 - 2.0 * r)] * 24, abs=1e-12)
    with pytest.raises(ValueError, match="AlphaBlend"):
        AlphaBlend(0.0, 0.6, 0.02)


@pytest.mark.unit
def test_the_overlay_adds_the_offsets_holds_the_last_quiet_gait_and_stays_off_while_fast():
    """Steady steps: the policy's gait passes unchanged (w = 0). The hip far behind the steps
    before: the offsets are added, from w >= hold onto the last gait chosen with w = 0, below
    it onto the policy's gait now. The same deficit while the hip's mean speed is more than
    ``fast_gate`` above the command (after a forward push): nothing added."""
    from rabbit_policy.runtime.policies import GaitCommand
    from rabbit_policy.runtime.recovery import OverlayConfig, RecoveryOverlay
    from rabbit_policy.runtime.speed_window import Observation

    taus = [i / 25 for i in range(1, 25)]
    quiet, now = GaitCommand(tuple([0.1] * 24), 5.0), GaitCommand(tuple([0.3] * 24), 6.0)

    def overlay_after_steady_steps(**config) -> RecoveryOverlay:
        overlay = _overlay(OverlayConfig(**config))
        for _ in range(5):  # five steps at the command's pace (the memory holds four)
            for tau in taus:
                assert overlay.apply(Observation(1.0, 1.0, 0.0, body=(0.0, 0.0, tau, 2.0, 1.0)), quiet) is quiet
        return overlay

    overlay = overlay_after_steady_steps(hold=0.5)
    behind = overlay.apply(Observation(1.0, 0.95, 0.05, body=(0.0, 0.0, 0.5, 2.0, 0.3)), now)
    assert overlay.last_weight == 1.0
    assert behind == overlay.rule.with_offsets(quiet, 1.0) != quiet  # onto the held quiet gait
    overlay = overlay_after_steady_steps(hold=1.0)
    slightly = overlay.apply(Observation(1.0, 0.95, 0.05, body=(0.0, 0.0, 0.5, 2.0, 0.8)), now)
    assert 0.0 < overlay.last_weight < 1.0
    assert slightly == overlay.rule.with_offsets(now, overlay.last_weight)  # below hold: onto the gait now
    overlay = overlay_after_steady_steps(fast_gate=0.1)
    assert overlay.apply(Observation(1.0, 1.2, -0.2, body=(0.0, 0.0, 0.5, 2.0, 0.3)), now) is now
    assert overlay.last_weight == 0.0
    overlay = overlay_after_steady_steps(fast_gate=0.0)  # never held off
    overlay.apply(Observation(1.0, 1.2, -0.2, body=(0.0, 0.0, 0.5, 2.0, 0.3)), now)
    assert overlay.last_weight == 1.0


@pytest.mark.unit
def test_from_rise_until_the_rules_weight_may_fall_but_not_rise_until_the_touchdown():
    """With ``rise_until`` 0.6: steady steps, then the hip falls behind late in a step (0.7 of
    phase). The weight stays at its value before 0.6 (0: nothing added) and may fall; after the
    touchdown the same deficit early in the step acts in full. Without the limit it acts at
    once, late in the step."""
    from rabbit_policy.runtime.policies import GaitCommand
    from rabbit_policy.runtime.recovery import OverlayConfig, RecoveryOverlay
    from rabbit_policy.runtime.speed_window import Observation

    taus = [i / 25 for i in range(1, 25)]
    gait = GaitCommand(tuple([0.1] * 24), 5.0)

    def behind_late(rise_until: float) -> RecoveryOverlay:
        overlay = _overlay(OverlayConfig(rise_until=rise_until))
        for _ in range(5):
            for tau in taus:
                overlay.apply(Observation(1.0, 1.0, 0.0, body=(0.0, 0.0, tau, 2.0, 1.0)), gait)
        for tau in [t for t in taus if t < 0.6]:
            overlay.apply(Observation(1.0, 1.0, 0.0, body=(0.0, 0.0, tau, 2.0, 1.0)), gait)
        overlay.apply(Observation(1.0, 0.95, 0.05, body=(0.0, 0.0, 0.7, 2.0, 0.3)), gait)
        return overlay

    assert behind_late(1.0).last_weight == 1.0
    limited = behind_late(0.6)
    assert limited.last_weight == 0.0
    limited.apply(Observation(1.0, 0.95, 0.05, body=(0.0, 0.0, 0.04, 2.0, 0.3)), gait)  # the next step
    assert limited.last_weight == 1.0


def _ship_policy():
    """``scripts/ship_policy.py`` as a module."""
    import importlib

    return importlib.import_module("rabbit_policy.commands.ship_policy")


def _overlay_file(tmp_path, at_once: bool = False, policy_blend: bool = False):
    """The shipped network with ``ship_policy.py --recovery-overlay``'s record (``at_once``:
    with ``--recovery-overlay-at-once``; ``policy_blend``: ``--recovery-overlay-policy-blend``),
    and without."""
    from rabbit_policy.runtime.network import PolicyCheckpoint
    from checkpoints import SHIPPED_BEFORE

    plain = tmp_path / "plain.pt"  # the shipped network, without any overlay it may ship with
    checkpoint = PolicyCheckpoint.load(SHIPPED_BEFORE)
    checkpoint.info.pop("recovery_overlay", None)
    checkpoint.save(plain)
    name = "overlay_policy_blend.pt" if policy_blend else "overlay_at_once.pt" if at_once else "overlay.pt"
    return _ship_policy().with_recovery_overlay(plain, tmp_path / name, at_once, policy_blend), plain


@pytest.mark.unit
def test_ship_policy_records_the_overlay_and_the_policy_reads_it(tmp_path):
    """The copy's checkpoint carries ``recovery_overlay``; the learned policy built from it reads
    the body state and asks for the controller's own blend (with ``--recovery-overlay-at-once``:
    gaits applied at once, the loops and the stack's configuration alike), and the card's
    regenerate line and rates say so. A policy deciding once per step or already on the
    recovery base is refused with one line."""
    from rabbit_policy.runtime.recovery import OverlayConfig

    ship = _ship_policy()
    network_text, rules_set_after_training, with_recovery_overlay = (
        ship.network_text, ship.rules_set_after_training, ship.with_recovery_overlay)
    overlaid, plain = _overlay_file(tmp_path)
    policy = make_policy("learned", policy_file=overlaid)
    assert policy.needs_body and policy.overlay is not None
    assert timing(policy) == DEFAULT_SETTINGS
    info = policy.checkpoint.info
    assert rules_set_after_training(info)[0].endswith(" --recovery-overlay")
    assert "recovery rule on top" in rules_set_after_training(info)[1]
    text = " ".join(network_text(info))
    assert "RecoveryOverlay" in text and "blended in" in text
    at_once, _ = _overlay_file(tmp_path, at_once=True)
    policy = make_policy("learned", policy_file=at_once)
    assert timing(policy) == CONTROLLER_SETTINGS
    assert rules_set_after_training(policy.checkpoint.info)[0].endswith(
        " --recovery-overlay --recovery-overlay-at-once")
    assert "no blend, no queue" in " ".join(network_text(policy.checkpoint.info))
    blending = make_policy("learned", policy_file=with_recovery_overlay(plain, tmp_path / "pb.pt", policy_blend=True))
    assert blending.overlay.config == OverlayConfig(at_once=True, policy_blend=True, rise_until=0.6)
    assert timing(blending) == CONTROLLER_SETTINGS
    assert rules_set_after_training(blending.checkpoint.info)[0].endswith(
        " --recovery-overlay --recovery-overlay-policy-blend")
    assert "blended in by the policy itself" in " ".join(network_text(blending.checkpoint.info))
    assert "from 0.6 of phase to the touchdown its weight may fall, not rise" in " ".join(
        network_text(blending.checkpoint.info))
    assert timing(make_policy("learned", policy_file=plain)) == DEFAULT_SETTINGS
    step_file = tmp_path / "per_step.pt"
    _zero_residual_on_recovery_file(step_file, base="classic")
    from rabbit_policy.runtime.network import PolicyCheckpoint

    checkpoint = PolicyCheckpoint.load(step_file)
    checkpoint.info["config"]["decision_period"] = 0
    checkpoint.save(step_file)
    with pytest.raises(ValueError, match="--recovery-overlay: .* once per step"):
        with_recovery_overlay(step_file, tmp_path / "x.pt")
    base_file = tmp_path / "on_recovery.pt"
    _zero_residual_on_recovery_file(base_file)
    with pytest.raises(ValueError, match="--recovery-overlay: .* already a residual on 'recovery'"):
        with_recovery_overlay(base_file, tmp_path / "y.pt")


@pytest.mark.sim
@pytest.mark.slow
def test_the_overlay_walks_the_network_until_a_push_and_survives_one_the_network_alone_does_not(tmp_path):
    """Undisturbed at 1.0 m/s the overlay never acts: the walk is the network's own to the bit.
    A -14 N s push at 0.875 of a step at 1.0 m/s (the network's binding phase there; its margin
    is 10 N s): the network alone falls or stalls, with the rule on top it walks on."""
    from rabbit_policy.evaluation.robustness import phase_times
    from rabbit_policy.spec.make import checkpoint_policy

    overlaid, plain = _overlay_file(tmp_path)
    with_rule, alone = make_policy("learned", policy_file=overlaid), checkpoint_policy(plain)
    quiet = [walk(policy, Scenario.constant(1.0), 6.0) for policy in (with_rule, alone)]
    assert np.array_equal(quiet[0].hip_x, quiet[1].hip_x)
    time = phase_times(with_rule, 1.0, 3.0, [0.875])[0]
    scenario = Scenario.constant(1.0, pushes=(Push(time, -140.0, 0.1),))
    assert walk(alone, scenario, time + 5.0).failed
    assert not walk(with_rule, scenario, time + 5.0).failed


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.parametrize("mode", ["blended", "at_once", "policy_blend"])
def test_lockstep_runs_the_learned_policy_with_the_overlay_as_the_ros_free_loop(tmp_path, mode):
    """Through a push the overlay acts on (its walk parts from the network's alone):
    policy_node builds the body state for it (the policy blend reads the phase and its rate
    too), run_stack's configuration gives the controller node the settings the checkpoint asks
    for, and every state is the ROS-free loop's."""
    from rabbit_policy.bringup.config import StackConfig
    from rabbit_policy.spec.make import checkpoint_policy
    from test_stack_nodes import _reference

    at_once = mode != "blended"
    overlaid, plain = _overlay_file(tmp_path, at_once, mode == "policy_blend")

    alone = checkpoint_policy(plain)  # the network without the overlay, under the same controller settings
    alone.controller_settings = CONTROLLER_SETTINGS if at_once else DEFAULT_SETTINGS

    pushes = (Push(2.4, -120.0, 0.1),)
    scenario = Scenario.constant(1.0, pushes=pushes)
    reference = _reference(3.5, policy=make_policy("learned", policy_file=overlaid), scenario=scenario)
    assert not np.array_equal(reference, _reference(3.5, policy=alone, scenario=scenario))
    config = StackConfig(duration=3.5, schedule=((0.0, 1.0),), controller="learned", policy_file=str(overlaid),
                         pushes=pushes)
    assert "within_step_blend" not in config.node_parameters()["hzd_controller_node"]  # started plain
    nodes = _assert_lockstep_is(config, reference)
    assert nodes["hzd_controller_node"].config.within_step_blend == (0.0 if at_once else 0.2)  # as announced


@pytest.mark.unit
def test_deciding_once_per_step_the_policy_runs_without_its_overlay_and_says_so(tmp_path):
    """The rule acts within the step: asked to decide once per step (``decision_period`` 0:
    ``--decision step``, ``policy_node decision_period:=0``), the learned policy loads without
    it, reads no body state, and its name says the rule is off. Its controller then runs with
    its defaults, in the loops and in run_stack's configuration alike, though the checkpoint's
    rule (policy blend) asks for gaits at once: the two once disagreed by a touchdown 2 ms late."""
    from rabbit_msgs_py.decision_ticks import DecisionTiming
    from rabbit_policy.bringup.config import StackConfig
    from rabbit_policy.spec.make import checkpoint_policy

    overlaid, _ = _overlay_file(tmp_path)
    per_step = checkpoint_policy(overlaid, PER_STEP)
    assert per_step.overlay is None and not per_step.needs_body
    assert per_step.name.endswith("(no recovery rule: once per step)")
    assert checkpoint_policy(overlaid).overlay is not None
    blending, _ = _overlay_file(tmp_path, at_once=True, policy_blend=True)
    assert timing(checkpoint_policy(blending, PER_STEP)) == DEFAULT_SETTINGS
    for decision in ("step", "own"):  # the stack starts the controller plain: it takes the policy's announced ones
        config = StackConfig(duration=1.0, schedule=((0.0, 1.0),), controller="learned", policy_file=str(blending),
                             decision=DecisionTiming.parse(decision))
        node = config.node_parameters()["hzd_controller_node"]
        assert not set(node) & set(controller_settings(checkpoint_policy(blending))), decision
