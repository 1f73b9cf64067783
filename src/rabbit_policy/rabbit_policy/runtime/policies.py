"""Gait policies: observation (:class:`~.speed_window.Observation`) -> gait for the next
step (24 Bezier coefficients alpha, derivative gain Kd). ROS-free; ``policy_node`` and the
scripts build one with :func:`rabbit_policy.spec.make.make_policy`. The controllers have one name each,
everywhere (CLI, parameters, results):

* ``classic``: classic HZD, the gait library (``rabbit_policy/gaits``), the gait nearest
  to the commanded speed or a linear blend of the two around it. Uses only v_d, unless
  given Westervelt's event-based speed integral (``speed_integral`` > 0, off by default:
  the paper's baseline has none), which commands the library the gait for v_d plus a
  bounded integral of the speed error (:mod:`.speed_integral`).
* ``learned``: HZD-RL, the network (:mod:`.forward`) and the rules its spec names (default:
  the packaged ``rabbit_policy/controllers/learned.yaml``; a training checkpoint ``.pt`` is
  built as its spec, :func:`rabbit_policy.spec.make.checkpoint_policy`).
* ``recovery``: the model-based push-recovery baseline (:mod:`.recovery`): classic HZD plus
  a hand-designed rule that bends the stance knee and swings the swing leg forward, at once,
  when the hip falls behind its gait. It reads the body state and runs the controller with
  gaits applied at once (``controller_settings``).

Older names are accepted as aliases (:data:`CONTROLLER_ALIASES`): ``hzd`` and ``library``
for classic, ``rl`` for learned.
"""

from __future__ import annotations

import copy
import sys

import numpy as np

from rabbit_hzd_controller.alpha import N_FREE, expand_alpha, reduce_alpha
from rabbit_policy.runtime.actions import residual_gate
from rabbit_policy.runtime.forward import NetworkForward
from rabbit_policy.runtime.classic import (CLASSIC_DECISION_PERIOD, DEFAULT_DECISION_WINDOW, LIBRARY_MODES,
                                           LibraryPolicy, PeriodicPolicy, RateLimitedPolicy)
from rabbit_policy.runtime.gait_command import (GaitCommand, Policy, PolicyUnavailable, controller_settings,
                                                decision_period, first_command, reset_policy)
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.speed_window import Observation

__all__ = ["CLASSIC_DECISION_PERIOD", "CONTROLLERS", "CONTROLLER_ALIASES", "CONTROLLER_CHOICES",
           "DEFAULT_DECISION_WINDOW", "GaitCommand", "LIBRARY_MODES", "LibraryPolicy",
           "NetworkPolicy", "PeriodicPolicy", "Policy", "PolicyUnavailable", "RateLimitedPolicy", "controller_name",
           "controller_settings", "copy_policy", "decision_period", "first_command",
           "read_only_memo", "reset_policy"]

CONTROLLERS = ("classic", "learned", "recovery")
CONTROLLER_ALIASES = {"hzd": "classic", "library": "classic", "rl": "learned"}
CONTROLLER_CHOICES = CONTROLLERS + tuple(CONTROLLER_ALIASES)
"""What a script's ``--controller`` accepts: the names and their aliases."""


def read_only_memo(policy: Policy | None) -> dict[int, object]:
    """A ``copy.deepcopy`` memo that shares the parts of ``policy`` no decision changes: gait
    libraries, and a network's numpy forward pass, weights and checkpoint. Deep copies of
    those cost about a hundred decisions each; the state decisions do change (a memory, a
    rate limit's command, the recovery rule's) is copied."""
    network = sys.modules.get("rabbit_policy.runtime.network")  # not imported: no torch network to share
    shared: tuple[type, ...] = (GaitLibrary, NetworkForward)
    if network is not None:
        shared += (network.PolicyCheckpoint, network.HZDPolicyNet)
    memo: dict[int, object] = {}
    seen: set[int] = set()
    stack: list[object] = [policy]
    while stack:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, shared):
            memo[id(obj)] = obj
        elif isinstance(obj, (list, tuple)):
            stack.extend(obj)
        elif isinstance(obj, dict):
            stack.extend(obj.values())
        elif type(obj).__module__.startswith("rabbit_") and hasattr(obj, "__dict__"):
            stack.extend(vars(obj).values())
    return memo


def copy_policy(policy: Policy) -> Policy:
    """An independent copy of ``policy`` and its decision state, sharing what no decision
    changes (:func:`read_only_memo`)."""
    return copy.deepcopy(policy, read_only_memo(policy))


class NetworkPolicy:
    """An HZD-RL network in memory (``HZDPolicyNet``): observation -> 20 free
    coefficients + Kd -> (alpha, Kd), decided by a numpy snapshot of the weights at construction
    (:class:`~.network.NetworkForward`: build another policy after they change; training
    builds one per evaluation).
    ``decision_period`` > 0: the network was trained to decide every that many ticks (the
    loops that run it read it, as for a :class:`PeriodicPolicy`). ``memory``: a network with
    :mod:`.memory`'s inputs keeps its integral and last action here (:meth:`reset` at the
    start of a walk; ``ClosedLoop`` and ``policy_node`` call it); with the body state it
    reads ``observation.body`` (``needs_body``). ``residual``: the network's output is a
    residual on the library (:class:`~.actions.ResidualAction`), not the gait itself;
    ``base``: on that policy's decision instead (:func:`rabbit_policy.spec.build.residual_base`: the recovery
    controller, whose body state and controller settings it then needs too). ``overlay``: the
    recovery rule on top of the network's gait (:class:`~.recovery.RecoveryOverlay`; it needs
    the body state, and the controller settings its configuration names)."""

    def __init__(self, net, name: str = "learned", decision_period: int = 0, memory=None, residual=None,
                 base: Policy | None = None, overlay=None) -> None:
        if base is not None and residual is None:
            raise ValueError("a base policy is what a residual adds to: give the residual too")
        if isinstance(net, NetworkForward):  # a spec's weights (rabbit_policy.spec.build): no torch
            self.net, self.forward = None, net
        else:  # a torch HZDPolicyNet (training): a numpy snapshot of its weights now
            self.net, self.forward = net, NetworkForward.of(net)
        self.name = name
        self.memory = memory
        self.residual = residual
        self.base = base
        self.overlay = overlay
        self._network_needs_body = (bool(memory is not None and memory.config.body)
                                    or bool(getattr(base, "needs_body", False)))
        self.needs_body = self._network_needs_body or overlay is not None
        if base is not None and controller_settings(base):
            self.controller_settings = controller_settings(base)
        if overlay is not None and overlay.controller_settings:
            self.controller_settings = overlay.controller_settings
        if decision_period:
            self.decision_period = decision_period
            self.decision_window = DEFAULT_DECISION_WINDOW

    def reset(self) -> None:
        """A new walk: the memory (if any) starts again (the last action: the residual's
        zero, or none)."""
        if self.memory is not None:
            self.memory.reset()
        reset_policy(self.base)
        reset_policy(self.overlay)

    def start_command(self, speed: float) -> GaitCommand:
        """The gait a walk starts on at ``speed`` m/s (before any state exists): the answer
        to (v, v, 0); a policy that reads the body state starts on the calibrated library's
        gait at ``speed`` (its residual's zero; the last action remembered as that)."""
        if self.base is not None:  # the base's own start (a zero residual)
            return self.base.start_command(speed)
        if not self._network_needs_body:  # an overlay starts on the network's own start
            observation = Observation(speed, speed, 0.0)
            return self.start_from(observation, self.forward(self.network_input(observation)))
        gait = (self.residual.library if self.residual is not None else GaitLibrary.load()).interpolate(speed)
        if self.residual is None:
            self._remember(np.append(gait.free, gait.kd))
        return GaitCommand(alpha=gait.alpha, kd=gait.kd)

    def start_from(self, observation: Observation, action: np.ndarray) -> GaitCommand:
        """The start gait from the network's ``action`` (physical units) on the start's
        observation (v, v, 0): the overlay, if any, starts on it (:meth:`start_command`; the
        learning env's first step)."""
        command = self.gait_from(observation, action)
        if self.overlay is not None:
            self.overlay.start(command)
        return command

    def _remember(self, action: np.ndarray) -> None:
        """Record the network-side action (physical units) in the memory, normalised to its bounds."""
        low, high = self.forward.low.astype(float), self.forward.high.astype(float)
        self.memory.record(2.0 * (action - low) / (high - low) - 1.0)

    def act(self, observation: Observation) -> GaitCommand:
        return self.decide(observation, self.forward(self.network_input(observation)))

    def decide(self, observation: Observation, action: np.ndarray) -> GaitCommand:
        """The gait for ``observation`` when the network's output is ``action`` (21 numbers,
        physical units): remembered, composed on its residual's base, the overlay on top.
        :meth:`act` with the network's own output; the learning env with the agent's
        (:class:`~rabbit_policy.learning.spec_env.SpecEnv`), so it learns in this very loop."""
        command = self.gait_from(observation, action)
        return command if self.overlay is None else self.overlay.apply(observation, command)

    def network_input(self, observation: Observation) -> np.ndarray | tuple:
        """What the network sees for ``observation`` (the memory's inputs update its integral:
        call once per decision, before :meth:`decide`)."""
        if self.memory is None:
            return observation.as_tuple()
        return self.memory.inputs(observation.as_tuple(), observation.body)

    def gait_from(self, observation: Observation, action: np.ndarray) -> GaitCommand:
        """The network's gait for its ``action`` (physical units; on its residual's base),
        before any overlay; the action remembered."""
        if self.memory is not None:
            self._remember(action)
        if self.base is not None:
            base = self.base.act(observation)
            action = self.residual.compose_on(action * residual_gate(self.base), np.append(reduce_alpha(base.alpha),
                                                                                         base.kd))
        elif self.residual is not None:
            action = self.residual.compose(action, observation.desired_speed,
                                           self.memory.integral if self.memory is not None else 0.0)
        return GaitCommand(alpha=tuple(float(a) for a in expand_alpha(action[:N_FREE])), kd=float(action[N_FREE]))


def controller_name(name: str) -> str:
    """The controller's one name (``classic``, ``learned`` or ``recovery``) for a name or an
    older alias (accepted quietly); raises ``ValueError`` naming the three."""
    canonical = CONTROLLER_ALIASES.get(name, name)
    if canonical not in CONTROLLERS:
        raise ValueError(f"controller must be one of {', '.join(CONTROLLERS)}, got {name!r}")
    return canonical


def controller_argument(text: str) -> str:
    """An argparse type: :func:`controller_name` (one line naming the three controllers)."""
    import argparse

    try:
        return controller_name(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
