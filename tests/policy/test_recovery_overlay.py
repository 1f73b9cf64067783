"""The recovery rule with a network: a residual on the recovery base, the recovery overlay on a
learned policy (the alpha blend, its rise and fall, what ship_policy records), and the ROS
stack running it as the ROS-free loop does."""

from __future__ import annotations

import numpy as np
import pytest

from rabbit_msgs_py.decision_ticks import PER_STEP

from rabbit_policy.experiment.loop import ClosedLoop, walk
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.runtime.policies import controller_settings
from rabbit_policy.spec.make import make_policy
from rabbit_policy.runtime.recovery import CONTROLLER_SETTINGS

from test_recovery import DEFAULT_SETTINGS, assert_lockstep_is, timing


def _overlay(config, period: int = 20, policy_blend: bool = False):
    """A RecoveryOverlay with the rule's constants as RecoveryConfig's and, with
    ``policy_blend``, the controller's default blend, gaits applied at once (a spec names
    both; these tests use the defaults)."""
    from rabbit_hzd_controller.controller import ControllerConfig
    from rabbit_policy.runtime.alpha_blend import AlphaBlend, BlendConfig
    from rabbit_policy.runtime.classic import LibraryPolicy
    from rabbit_policy.runtime.gait_library import GaitLibrary
    from rabbit_policy.runtime.recovery import RecoveryOverlay, RecoveryPolicy

    rule = RecoveryPolicy(LibraryPolicy(GaitLibrary.load(), "interpolate"), decision_period=max(period, 1))
    defaults = ControllerConfig()
    blend = (AlphaBlend(BlendConfig(defaults.within_step_blend, defaults.within_step_until), period * defaults.tick)
             if policy_blend else None)
    return RecoveryOverlay(config, period, rule, blend, at_once=policy_blend)


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
    blending = _overlay(OverlayConfig(), policy_blend=True)
    assert blending.controller_settings == CONTROLLER_SETTINGS and _overlay(OverlayConfig()).controller_settings == {}
    with pytest.raises(ValueError, match="only when the controller applies them at once"):
        RecoveryOverlay(OverlayConfig(), 20, blending.rule, blending._blend, at_once=False)
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
    from rabbit_policy.runtime.alpha_blend import AlphaBlend, BlendConfig

    rng = np.random.default_rng(3)
    blend = AlphaBlend(BlendConfig(0.2, 0.6), 0.02)
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
    from rabbit_policy.runtime.alpha_blend import AlphaBlend, BlendConfig

    blend = AlphaBlend(BlendConfig(0.2, 0.6), 0.02)
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
    with pytest.raises(ValueError, match="alpha blend needs a length and until in"):
        BlendConfig(0.0, 0.6)


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
    assert blending.overlay.config == OverlayConfig(rise_until=0.6) and blending.overlay._blend is not None
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
    from stack_helpers import loop_states

    at_once = mode != "blended"
    overlaid, plain = _overlay_file(tmp_path, at_once, mode == "policy_blend")

    alone = checkpoint_policy(plain)  # the network without the overlay, under the same controller settings
    alone.controller_settings = CONTROLLER_SETTINGS if at_once else DEFAULT_SETTINGS

    pushes = (Push(2.4, -120.0, 0.1),)
    scenario = Scenario.constant(1.0, pushes=pushes)
    reference = loop_states(3.5, policy=make_policy("learned", policy_file=overlaid), scenario=scenario)
    assert not np.array_equal(reference, loop_states(3.5, policy=alone, scenario=scenario))
    config = StackConfig(duration=3.5, schedule=((0.0, 1.0),), controller="learned", policy_file=str(overlaid),
                         pushes=pushes)
    assert "within_step_blend" not in config.node_parameters()["hzd_controller_node"]  # started plain
    nodes = assert_lockstep_is(config, reference)
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

