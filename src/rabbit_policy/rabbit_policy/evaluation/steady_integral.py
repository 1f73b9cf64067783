"""The speed integral's steady value per commanded speed, measured: the table of an
:class:`~rabbit_policy.runtime.speed_integral.IntegralFeedforward`.

For each speed, a walk at that constant command on the nominal model (the policy's own
rules, no feed-forward); I* is the mean of I over the policy's decisions after ``settle`` s.
A mean, not a last value: at some speeds the shipped network's walk and its integral swing
slowly about their steady values (at 0.8 m/s I swings between about −0.25 and 0 m, the
hip between 0.64 and 0.89 m/s: docs/learning.md, 2026-11-27 (seventh)).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.policies import NetworkPolicy
from rabbit_policy.runtime.speed_integral import IntegralFeedforward
from rabbit_policy.spec import ControllerSpec, build, dump_spec, load_controller, load_spec, packaged_spec


class _IntegralRecorder:
    """A memory policy, recording its integral (m) after each decision; everything else is
    the policy's own."""

    def __init__(self, policy: NetworkPolicy) -> None:
        self._policy = policy
        self.values: list[float] = []

    def __getattr__(self, name: str):
        return getattr(self._policy, name)

    def act(self, observation):
        command = self._policy.act(observation)
        self.values.append(self._policy.memory.integral)
        return command


def steady_integral(policy: NetworkPolicy, speed: float, duration: float = 60.0, settle: float = 10.0) -> float:
    """I* (m): the mean of ``policy``'s integral over the decisions from ``settle`` s to
    ``duration`` s of a walk at ``speed`` m/s. ``ValueError`` if the walk fails or the policy
    keeps no integral."""
    if policy.memory is None:
        raise ValueError(f"{policy.name} keeps no speed integral (features 'paper')")
    if not 0.0 <= settle < duration:
        raise ValueError(f"need 0 <= settle < duration (s), got {settle!r} and {duration!r}")
    recorder = _IntegralRecorder(policy)
    result = walk(recorder, Scenario(schedule=((0.0, float(speed)),)), duration)
    if result.failed:
        raise ValueError(f"{policy.name} did not walk {duration:g} s at {speed:g} m/s; no steady integral there")
    decisions = len(recorder.values)
    return float(np.mean(recorder.values[int(decisions * settle / duration):]))


def steady_integrals(policy: NetworkPolicy, speeds: tuple[float, ...], duration: float = 60.0,
                     settle: float = 10.0) -> IntegralFeedforward:
    """The feed-forward table of ``policy`` (a memory policy): :func:`steady_integral` at each
    of ``speeds`` (m/s, increasing), measured on its network with the memory as it is but
    without a feed-forward (the table does not measure itself) and without a recovery overlay
    (the network's own steady integral; the overlay answers pushes and stalls, and at a
    constant command it stirs only on the slow oscillation's near-stall steps)."""
    if policy.memory is None:
        raise ValueError(f"{policy.name} keeps no speed integral (features 'paper')")
    without = network_alone(policy)
    return IntegralFeedforward(tuple(speeds), tuple(round(steady_integral(without, v, duration, settle), 4)
                                                    for v in speeds))


def network_alone(policy: NetworkPolicy) -> NetworkPolicy:
    """``policy``'s spec (:func:`rabbit_policy.spec.build` records it) built again with its
    network's weights, without a feed-forward and without the overlay (the controller then
    as the spec's kind runs without one: the classic spec's timing), a residual on the
    recovery rule kept."""
    spec = policy.spec
    integral = replace(spec.speed_integral, feedforward=None)
    if spec.overlay is not None:
        classic = load_spec(packaged_spec("classic"))
        on_rule = spec.network.residual is not None and spec.network.residual.base != "classic"
        spec = replace(spec, overlay=None, blend=None, recovery_rule=spec.recovery_rule if on_rule else None,
                       controller=spec.controller if on_rule else classic.controller)
    forward = policy.forward
    return build(replace(spec, speed_integral=integral), policy.spec_base,
                 weights=(list(forward.weights), list(forward.biases)),
                 source=policy.name.removeprefix("learned/").split("@")[0] + " (network alone)")  # named once


def calibrate_spec(path: str | Path) -> ControllerSpec:
    """Re-measure the feed-forward table of the learned spec file ``path`` on that spec's own
    controller (:func:`steady_integrals` at the table's speeds, the table's ``start`` kept) and
    write the spec back with it: a start calibrated to itself, so the rules alone are at
    their best before training. Returns the spec written. ``ValueError`` if the spec has no
    feed-forward table."""
    path = Path(path)
    spec = load_spec(path)
    table = spec.speed_integral.feedforward if spec.speed_integral is not None else None
    if table is None:
        raise ValueError(f"{path}: no speed_integral.feedforward table to calibrate")
    measured = steady_integrals(load_controller(path), tuple(table.speeds))
    calibrated = replace(spec, speed_integral=replace(spec.speed_integral, feedforward=replace(
        table, values=tuple(measured.values))), provenance={**spec.provenance, "feedforward": (
            "re-measured on this spec's own controller (rabbit_policy.evaluation.steady_integral.calibrate_spec)")})
    dump_spec(calibrated, path, f"{spec.name}, its feed-forward re-measured on itself "
                                "(rabbit_policy.evaluation.steady_integral.calibrate_spec)")
    return calibrated
