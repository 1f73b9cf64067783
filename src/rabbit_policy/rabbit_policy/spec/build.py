"""``build(spec)``: a controller spec (:mod:`.schema`) assembled into the policy that runs it,
every constant from the spec, none from a code default (ROS-free, no torch). Each stage is
the runtime's one implementation (:mod:`rabbit_policy.runtime`); what ``controller`` names
is what the 1 kHz controller must run with (``policy.controller_settings``: the loops and
the stack apply it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rabbit_hzd_controller.controller import ControllerConfig
from rabbit_policy.runtime.actions import ActionBounds, ResidualAction
from rabbit_policy.runtime.alpha_blend import AlphaBlend
from rabbit_policy.runtime.classic import LibraryPolicy, PeriodicPolicy
from rabbit_policy.runtime.forward import NetworkForward
from rabbit_policy.runtime.gait_command import Policy
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.memory import INPUTS, MemoryConfig, SpeedMemory
from rabbit_policy.runtime.policies import NetworkPolicy
from rabbit_policy.runtime.recovery import RecoveryConfig, RecoveryOverlay, RecoveryPolicy
from rabbit_policy.runtime.speed_integral import IntegralConfig
from rabbit_policy.spec.files import checked_library_dir, load_weights, packaged_spec
from rabbit_policy.spec.schema import ControllerSpec, NetworkSpec, SpecError, load_spec
from rabbit_sim.physics.model import model_sha256


def load_controller(path: str | Path) -> Policy:
    """The controller the spec file ``path`` describes (its files beside it)."""
    path = Path(path)
    return build(load_spec(path), path.parent, source=path.name)


def load_packaged(kind: str) -> Policy:
    """The shipped controller ``kind`` (classic, recovery, learned) from its spec in the package."""
    return load_controller(packaged_spec(kind))


def build(spec: ControllerSpec, base: Path | None = None, weights: tuple[list, list] | None = None,
          source: str = "") -> Policy:
    """The policy ``spec`` describes. ``base``: the directory its files are named relative to;
    ``weights``: the network's (weight matrices, bias vectors) when they are in memory (a
    checkpoint being converted) instead of in the file the spec names; ``source``: for the
    policy's name. :class:`~.schema.SpecError` with one line for a spec that cannot be
    built (a file whose hash differs, an architecture its weights do not have)."""
    base = Path(base) if base is not None else Path.cwd()
    if spec.controller.model_sha256 != model_sha256():
        raise SpecError(f"controller.model_sha256 {spec.controller.model_sha256[:12]}: the spec was made for another "
                        f"robot model than rabbit_sim's ({model_sha256()[:12]}), whose geometry the controller assumes")
    library = GaitLibrary.load(checked_library_dir(spec.gait_library.source, spec.gait_library.sha256, base))
    period, window = spec.decision.period_ticks, spec.decision.window_ticks  # checked by DecisionSpec
    integral = spec.speed_integral  # the runtime's IntegralConfig, read from its section
    try:
        if spec.kind == "learned":
            policy = _learned(spec, base, library, integral, weights, source)
        else:
            classic = LibraryPolicy(library, spec.gait_library.mode, integral)
            if spec.kind == "recovery":
                policy = RecoveryPolicy(classic, spec.recovery_rule, period, window)
            else:
                policy = PeriodicPolicy(classic, period, window) if period else classic
    except SpecError:
        raise
    except ValueError as exc:
        raise SpecError(f"{spec.kind} spec {source or spec.name}: {exc}") from None
    policy.controller_settings = spec.controller.settings()
    policy.spec, policy.spec_base = spec, base
    return policy


def residual_base(base: str, library: GaitLibrary, rule: RecoveryConfig, decision_period: int,
                  window: int) -> RecoveryPolicy:
    """What a residual on ``base`` (``recovery``, ``recovery_gated``) adds to: the recovery
    rule ``rule`` on the interpolated ``library``, deciding every ``decision_period`` ticks; with
    ``recovery_gated`` the residual is scaled by the rule's weight."""
    policy = RecoveryPolicy(LibraryPolicy(library, "interpolate"), rule, decision_period, window)
    policy.gates_residual = base == "recovery_gated"
    return policy


def network_forward(spec: NetworkSpec, base: Path, weights: tuple[list, list] | None = None) -> NetworkForward:
    """The network's numpy forward pass: its numbers from the spec, its weights from the
    weights file (hash checked) or ``weights``; the architecture checked against them."""
    layers = len(spec.hidden) + 1
    if weights is None:
        weights = load_weights(spec.weights.file, spec.weights.sha256, base, layers)
    matrices, biases = weights
    widths = [spec.inputs, *spec.hidden, spec.outputs]
    for k, (w, b) in enumerate(zip(matrices, biases)):
        if np.shape(w) != (widths[k + 1], widths[k]) or np.shape(b) != (widths[k + 1],):
            raise SpecError(f"network layer {k} is {np.shape(w)}, the spec's architecture "
                            f"{' -> '.join(map(str, widths))} needs {(widths[k + 1], widths[k])}")
    # (the arrays' lengths against the architecture: NetworkSpec checks them where the spec is read)
    try:
        return NetworkForward.from_arrays(matrices, biases, spec.input_offset, spec.input_scale, spec.low, spec.high,
                                          spec.output)
    except ValueError as exc:
        raise SpecError(f"network: {exc}") from None


def _learned(spec: ControllerSpec, base: Path, library: GaitLibrary, integral: IntegralConfig | None,
             weights: tuple[list, list] | None, source: str) -> Policy:
    net = spec.network
    period, window = spec.decision.period_ticks, spec.decision.window_ticks
    if net.features not in INPUTS or INPUTS[net.features] != net.inputs:
        raise SpecError(f"network.features {net.features!r} with {net.inputs} inputs: features take "
                        f"{ {k: v for k, v in INPUTS.items()} }")
    forward = network_forward(net, base, weights)
    memory = None
    if net.features != "paper":
        if integral is None:
            raise SpecError(f"network.features {net.features!r} keep the speed integral: speed_integral is needed")
        memory = SpeedMemory(MemoryConfig(integral, net.features == "body"))
    residual = on_rule = None
    if net.residual is not None:
        margin = net.residual.bounds_margin if net.residual.bounds_margin is not None else float("inf")
        bounds = ActionBounds.from_library(library, margin, net.residual.kd_bounds,
                                           ControllerConfig(**spec.controller.settings()))
        residual = ResidualAction(library, bounds, tuple(net.residual.scale),
                                  integral.gain if integral is not None else 0.0)
        if net.residual.base != "classic":  # on the recovery rule's decision (the spec's rule)
            if period < 1:
                raise SpecError(f"a residual on base {net.residual.base} decides within the step: "
                                "decision.period_ticks must be >= 1")
            on_rule = residual_base(net.residual.base, library, spec.recovery_rule, period, window)
    overlay = None
    if spec.overlay is not None:
        at_once = spec.controller.within_step_blend == 0.0 and spec.controller.within_step_until == 1.0
        if spec.blend is not None and not at_once:
            raise SpecError("blend: the network's gaits are blended by the overlay only when the controller applies "
                            "gaits at once (controller.within_step_blend 0, within_step_until 1)")
        rule = RecoveryPolicy(LibraryPolicy(library, "interpolate"), spec.recovery_rule, period, window)
        blend = (AlphaBlend(spec.blend, period * ControllerConfig.tick)
                 if spec.blend is not None else None)
        overlay = RecoveryOverlay(spec.overlay, period, rule, blend, at_once)
    name = f"learned/{source or spec.name}" + (f"@{period}ticks" if period else "")
    policy = NetworkPolicy(forward, name, period, memory, residual, on_rule, overlay)
    if period:
        policy.decision_window = window
    return policy
