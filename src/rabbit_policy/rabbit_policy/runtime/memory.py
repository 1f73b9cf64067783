"""Memory for the policy (the learning issue's ablation row b): besides the paper's three
inputs, the integral of the speed error with anti-windup and the last action.

A memoryless map from (v_d, v̄, v_d - v̄) to a gait can only correct a steady speed error in
proportion to it (a model error such as the ``drives`` model's gear friction leaves one); an integral removes it
(Westervelt et al., IEEE TAC 2003: an event-based PI controller on RABBIT), and the last
action lets the policy change its gait smoothly. :class:`SpeedMemory` is the one
implementation, run by the learning environment and by :class:`NetworkPolicy` (``walk.py``,
the evaluations, ``policy_node``), so a policy sees in the loops what it saw in training.

Inputs, in order: the paper's three (m/s), then the integral (m: the sum of the mean speed
error v_d - v̄ times the decision interval, clamped to +-``limit``: anti-windup), then the
last action normalised to [-1, 1] (21 numbers; at the start the gait the robot starts on).
With ``body`` (features ``"body"``, the ablation's row c) the five body-state numbers of
:mod:`.body` follow (torso pitch and rate, phase and rate, hip velocity): 30 inputs.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from rabbit_policy.runtime.body import N_BODY
from rabbit_policy.runtime.speed_integral import (IntegralConfig, SpeedIntegral, WindupDecay,
                                                  decision_dt, integral_limit)

N_ACTION = 21
DEFAULT_LIMIT = 0.2
"""The integral's bound (m) unless an integral gain sets it."""
FEATURES = ("paper", "memory", "body")
INPUTS = {"paper": 3, "memory": 3 + 1 + N_ACTION, "body": 3 + 1 + N_ACTION + N_BODY}


def check_features(features: str, decision_period: int, integral_gain: float = 0.0) -> None:
    """``ValueError`` for features that are not :data:`FEATURES` or do not go with the
    decision period (ticks) or the integral gain (1/s)."""
    if features not in FEATURES:
        raise ValueError(f"features must be one of {FEATURES}, got {features!r}")
    if features == "body" and not decision_period:
        raise ValueError("features 'body' (the body state inside the step) needs a decision period > 0")
    if features == "paper" and integral_gain:
        raise ValueError("an integral gain offsets the base gait by the memory's integral: it needs "
                         "features memory or body")


@dataclass(frozen=True)
class MemoryConfig:
    """``integral``: the speed integral's configuration (the anti-windup bound, the seconds
    between decisions, the gain and range gate, band, clip, windup decay and feed-forward:
    :class:`~.speed_integral.IntegralConfig`); ``body``: the body state follows."""

    integral: IntegralConfig
    body: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.integral, IntegralConfig):
            raise ValueError(f"the memory's integral must be an IntegralConfig, got {self.integral!r}")
        if not isinstance(self.body, bool):
            raise ValueError(f"the memory's body must be True or False, got {self.body!r}")

    def with_integral(self, **changes) -> "MemoryConfig":
        """This memory with the integral's fields ``changes`` replaced (checked again)."""
        return replace(self, integral=replace(self.integral, **changes))

    def to_dict(self) -> dict:
        """One flat dict, as a checkpoint's ``memory`` stores it: the integral's fields and ``body``."""
        return {**self.integral.to_dict(), "body": self.body}

    @classmethod
    def from_dict(cls, info: dict) -> "MemoryConfig":
        """The memory a checkpoint's ``memory`` records (:meth:`to_dict`; a checkpoint from
        before a rule existed has no field for it: that rule is off); ``ValueError`` for a bad one."""
        info = dict(info)
        body = info.pop("body", False)
        info.setdefault("limit", DEFAULT_LIMIT)
        return cls(IntegralConfig.from_dict(info), body)

    @classmethod
    def for_period(cls, decision_period: int, limit: float = DEFAULT_LIMIT, body: bool = False,
                   band: float | None = None, clip: float | None = None,
                   windup_decay: WindupDecay | None = None) -> "MemoryConfig":
        """The memory of a policy deciding every ``decision_period`` ticks of 1 ms (0: once
        per walking step, about 0.6 s)."""
        return cls(IntegralConfig(limit, decision_dt(decision_period), band=band, clip=clip, windup_decay=windup_decay),
                   body)

    @classmethod
    def for_features(cls, features: str, decision_period: int, integral_gain: float = 0.0,
                     speed_range: tuple[float, float] | None = None, band: float | None = None,
                     clip: float | None = None, windup_decay: WindupDecay | None = None) -> "MemoryConfig | None":
        """The memory a policy with ``features`` (:data:`FEATURES`) keeps; None for the paper's.
        ``integral_gain`` > 0 (1/s): its integral also offsets a residual's base gait by
        ``integral_gain * I`` m/s, so I is bounded by
        :func:`~.speed_integral.integral_limit` (the offset within +-0.2 m/s) and held where
        the base gait would leave ``speed_range`` (m/s: the library's speeds; needed with a gain).
        ``band``, ``clip`` (m/s; None: none), ``windup_decay`` (None: none): the integral's
        anti-windup (:class:`~.speed_integral.IntegralConfig`)."""
        check_features(features, decision_period, integral_gain)
        if features == "paper":
            if band is not None or clip is not None or windup_decay is not None:
                raise ValueError("an integral band, clip or windup decay needs the speed integral: features memory "
                                 "or body")
            return None
        if not integral_gain:
            return cls.for_period(decision_period, DEFAULT_LIMIT, features == "body", band, clip, windup_decay)
        if speed_range is None:
            raise ValueError("a memory whose integral offsets the base gait needs the library's speed range")
        return cls(IntegralConfig(integral_limit(integral_gain), decision_dt(decision_period), integral_gain,
                                  speed_range, band, clip, windup_decay), features == "body")


class SpeedMemory:
    """The integral and the last action (see the module docstring). Call :meth:`inputs` once
    per decision, then :meth:`record` with the action taken."""

    def __init__(self, config: MemoryConfig) -> None:
        self.config = config
        self._integral = SpeedIntegral(config.integral)
        self.reset()

    @property
    def integral(self) -> float:
        """The integral of the speed error so far (m), within +-``config.integral.limit``."""
        return self._integral.value

    def reset(self, last_action: np.ndarray | None = None) -> None:
        """A new walk: the integral at 0, the last action ``last_action`` (normalised; None: 0)."""
        self._integral.reset()
        self.last_action = np.zeros(N_ACTION) if last_action is None else np.asarray(last_action, dtype=float).copy()

    def inputs(self, paper: np.ndarray, body: tuple[float, ...] | None = None) -> np.ndarray:
        """The network's inputs for this decision from the paper's three (v_d, v̄, v_d - v̄)
        and, with ``config.body``, the body state (:func:`.body.body_state`)."""
        paper = np.asarray(paper, dtype=float)
        if self.config.body and (body is None or len(body) != N_BODY):
            raise ValueError(f"this policy needs the body state ({N_BODY} numbers) with each observation")
        parts = [paper, [self._integral.update(paper[2], paper[0])], self.last_action] + ([np.asarray(body, dtype=float)] if self.config.body else [])
        return np.concatenate(parts)

    def record(self, normalised_action: np.ndarray) -> None:
        """The action just taken, normalised to [-1, 1]."""
        self.last_action = np.clip(np.asarray(normalised_action, dtype=float), -1.0, 1.0)
