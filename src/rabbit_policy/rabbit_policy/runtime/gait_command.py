"""What every gait policy shares (ROS-free): the command it decides (:class:`GaitCommand`),
the :class:`Policy` protocol, and the small functions the loops, ``policy_node`` and the
builders use to start, reset and read a policy."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from rabbit_policy.runtime.speed_window import Observation


@dataclass(frozen=True)
class GaitCommand:
    """What a policy decides for the next step: alpha (24, rad, core order) and Kd
    (N m s/rad)."""

    alpha: tuple[float, ...]
    kd: float


class Policy(Protocol):
    """Anything that maps an observation to a gait command."""

    name: str

    def act(self, observation: Observation) -> GaitCommand: ...


class PolicyUnavailable(RuntimeError):
    """The requested policy cannot be loaded (missing files, not shipped yet)."""



def first_command(policy: Policy, speed: float) -> GaitCommand:
    """The gait a policy starts on at ``speed`` m/s (the loops and ``policy_node``): its
    ``start_command`` if it has one (a policy that reads the body state), else its answer to
    (v, v, 0)."""
    start = getattr(policy, "start_command", None)
    return start(speed) if start is not None else policy.act(Observation(speed, speed, 0.0))


def reset_policy(policy: Policy | None) -> None:
    """Start a policy's walk afresh: a stateful one (memory, a rate limit) has ``reset``."""
    reset = getattr(policy, "reset", None)
    if reset is not None:
        reset()


def controller_settings(policy: Policy | None) -> dict[str, float]:
    """The ``ControllerConfig`` fields a policy needs the controller to run with (the
    recovery controller: gaits applied at once); {} for the rest. The loops apply them, and
    the stack gives them to ``hzd_controller_node`` as parameters."""
    return dict(getattr(policy, "controller_settings", {}))



def decision_period(policy: Policy | None) -> int:
    """Ticks between a policy's decisions; 0: once per step, at the touchdown, for the next
    step (every policy but a :class:`PeriodicPolicy`)."""
    return getattr(policy, "decision_period", 0)


