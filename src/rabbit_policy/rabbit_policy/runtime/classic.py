"""Classic HZD as a policy (ROS-free): the gait library's gait for the command
(:class:`LibraryPolicy`, optionally with Westervelt's event-based speed integral), and the
two wrappers any policy may wear: a command rate limit (:class:`RateLimitedPolicy`) and
decisions every N ticks (:class:`PeriodicPolicy`)."""

from __future__ import annotations

import math

from rabbit_msgs_py.decision_ticks import check_ticks

from rabbit_policy.runtime.gait_command import GaitCommand, Policy, controller_settings, decision_period, reset_policy
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.speed_integral import DEFAULT_OFFSET_LIMIT, IntegralConfig, SpeedIntegral, integral_limit
from rabbit_policy.runtime.speed_window import Observation

LIBRARY_MODES = ("nearest", "interpolate")


def classic_integral(gain: float, dt: float, speed_range: tuple[float, float],
                     offset_limit: float = DEFAULT_OFFSET_LIMIT) -> IntegralConfig:
    """Westervelt's event-based speed integral for classic HZD: gain (1/s), updated every
    ``dt`` s, the offset ``gain * I`` within +-``offset_limit`` m/s and I held where the
    commanded gait would leave ``speed_range`` (the library's speeds, m/s)."""
    return IntegralConfig(integral_limit(gain, offset_limit), dt, gain, tuple(speed_range))


class LibraryPolicy:
    """Classic HZD: the library gait for the commanded speed (``nearest`` or
    ``interpolate``); the measured speeds are not used. With a speed ``integral``
    (:class:`~.speed_integral.IntegralConfig`, gain > 0 in 1/s) the gait is the one for
    ``v_d + gain * I``, I the integral of the mean speed error (:mod:`.speed_integral`:
    Westervelt's event-based integral, updated every ``dt`` s, bounded, and held where
    ``v_d + gain * I`` would leave the library's speeds: :func:`classic_integral`);
    :meth:`reset` zeroes it for a new walk."""

    def __init__(self, library: GaitLibrary, mode: str = "nearest", integral: IntegralConfig | None = None) -> None:
        if mode not in LIBRARY_MODES:
            raise ValueError(f"library mode must be one of {LIBRARY_MODES}, got {mode!r}")
        if integral is not None and not integral.gain > 0.0:
            raise ValueError(f"a classic speed integral needs a gain > 0 (1/s), got {integral.gain!r}")
        self.library = library
        self.mode = mode
        self.integral_gain = integral.gain if integral is not None else 0.0
        self.integral = SpeedIntegral(integral) if integral is not None else None
        gain = self.integral_gain
        self.name = f"classic/{mode}" + (f"+integral{gain:g}" if gain else "")

    def reset(self) -> None:
        """A new walk: the speed integral (if any) at 0."""
        if self.integral is not None:
            self.integral.reset()

    def act(self, observation: Observation) -> GaitCommand:
        speed = observation.desired_speed
        if self.integral is not None:
            speed += self.integral_gain * self.integral.update(observation.mean_error, speed)
        gait = self.library.nearest(speed) if self.mode == "nearest" else self.library.interpolate(speed)
        return GaitCommand(alpha=gait.alpha, kd=gait.kd)


class RateLimitedPolicy:
    """A policy whose command follows the requested one by at most ``max_step`` m/s per
    decision (per walking step, or per decision of a policy deciding every N ticks): the usual rate limit on a scheduled gait library. The
    inner policy sees the limited command, and the speed error input consistently
    (mean(v_d - v) shifted by the limited minus the requested command). Stateful: the
    first decision starts at the requested command."""

    def __init__(self, policy: Policy, max_step: float) -> None:
        if not (math.isfinite(max_step) and max_step > 0.0):
            raise ValueError(f"the command rate limit must be a finite number > 0 m/s per step, got {max_step}")
        self.policy = policy
        self.max_step = max_step
        self.name = f"{policy.name}+limit{max_step:g}"
        self.needs_body = getattr(policy, "needs_body", False)
        if self.needs_body:  # it starts on its own gait (no body state before the walk)
            self.start_command = policy.start_command
        self.controller_settings = controller_settings(policy)
        self.command: float | None = None
        if decision_period(policy):  # a learned policy trained to decide every N ticks: keep its rate
            self.decision_period, self.decision_window = policy.decision_period, policy.decision_window

    def reset(self) -> None:
        """A new walk: the first decision starts at the requested command again."""
        self.command = None
        reset_policy(self.policy)

    def act(self, observation: Observation) -> GaitCommand:
        wanted = observation.desired_speed
        if self.command is None:
            self.command = wanted
        else:
            self.command += min(self.max_step, max(-self.max_step, wanted - self.command))
        shift = self.command - wanted
        return self.policy.act(Observation(self.command, observation.mean_speed, observation.mean_error + shift,
                                           observation.body))


CLASSIC_DECISION_PERIOD = 20
"""Ticks between the classic controller's decisions unless told otherwise: deciding every
20 ticks with the gait blended in at once falls in fewer speed changes than once per step
(docs/evaluation.md, "What changed, and why", measures it)."""

DEFAULT_DECISION_WINDOW = 1000
"""Longest moving-average window (ticks, 1 ms) of a policy deciding every N ticks; the
average spans the last step's duration (0.36-0.73 s), this only bounds it."""


class PeriodicPolicy:
    """A policy that decides every ``decision_period`` control ticks (1 ms) instead of once per step,
    as the paper evaluates its network at every simulation step: its observation is the
    moving average over the last step's duration (at most ``window`` ticks), and its gait applies at once, blended in
    from the outputs in force (``HZDController.apply_now``: continuous outputs). The loop
    that runs it reads ``decision_period``/``decision_window``; ``act`` is the inner
    policy's."""

    def __init__(self, policy: Policy, decision_period: int, window: int = DEFAULT_DECISION_WINDOW) -> None:
        check_ticks(decision_period)
        check_ticks(window, "the decision window")
        self.policy = policy
        self.decision_period = decision_period
        self.decision_window = window
        self.name = f"{policy.name}@{decision_period}ticks"
        self.needs_body = getattr(policy, "needs_body", False)
        if self.needs_body:  # it starts on its own gait (no body state before the walk)
            self.start_command = policy.start_command

    def reset(self) -> None:
        reset_policy(self.policy)

    def act(self, observation: Observation) -> GaitCommand:
        return self.policy.act(observation)


