"""The integral of the speed error with anti-windup: the one implementation of that rule.

``I = clamp(I + (v_d - v̄) dt, -limit, +limit)`` per decision (m: m/s times s), with
``v_d - v̄`` the observation's mean speed error and ``dt`` the time between decisions;
conditional integration: at the bound the sum stops growing, so it unwinds at once when the
error turns (with a ``band``, it also integrates only errors smaller than the band; with a
``clip``, the error clipped; with a :class:`WindupDecay`, what it wound up after a change of
the command decays once the hip has passed the new command). Where I offsets the library's
gait (below), it is also held where that gait ``v_d + gain * I`` would leave the library's
speeds (:class:`IntegralConfig`'s ``speed_range``): beyond them ``interpolate`` clamps, so
anything integrated there is windup (docs/learning.md, 2026-11-24 (night), "the range gate"). Its users:

* :class:`~.memory.SpeedMemory`: the learned policy's memory input is I itself;
* Westervelt's event-based integral (Westervelt, Grizzle, Koditschek, IEEE TAC 2003: an
  event-based PI controller removes RABBIT's steady speed error): the library's gait is
  taken for ``v_d + gain * I`` (:func:`offset_limit_integral` bounds I so that the offset
  stays within +-``offset_limit`` m/s). The classic controller with ``speed_integral`` > 0
  (:class:`~.policies.LibraryPolicy`) and a residual policy with ``integral_gain`` > 0
  (:class:`~.actions.ResidualAction`, its zero residual being that classic controller) use
  it, the same arithmetic in the same order, so they agree bit for bit.

A steady error (a model error, a torque delay) is what a memoryless gait choice cannot
remove: it corrects only in proportion to the error it sees.
"""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import asdict, dataclass
from typing import ClassVar
from math import isfinite

NOMINAL_STEP_S = 0.6
"""A walking step's duration (s): the integral's dt for decisions once per step."""

DEFAULT_OFFSET_LIMIT = 0.2
"""Bound (m/s) on the integral's speed offset on the library: beyond it the library's
fastest gaits walk *slower* on the ``drives`` model, and a larger offset winds up into them
(docs/learning.md)."""


SPEED_INTEGRAL_HELP = ("classic: Westervelt's event-based speed integral, gain in 1/s (the gait for the command "
                       "plus a bounded integral of the speed error; 0 = off, the default: the paper's baseline)")
"""The command lines' help for ``--speed-integral`` (walk.py, run_stack.py)."""


def check_gain(gain: float, name: str) -> float:
    """``gain`` (1/s) as a float if finite and >= 0 (0: no integral); else ``ValueError``
    naming it ``name``."""
    if not (isfinite(gain) and gain >= 0.0):
        raise ValueError(f"{name} must be a finite number >= 0 (1/s; 0 = off), got {gain!r}")
    return float(gain)


def decision_dt(decision_period: int) -> float:
    """Seconds between decisions every ``decision_period`` ticks of 1 ms (0: once per
    walking step, :data:`NOMINAL_STEP_S`)."""
    return decision_period / 1000.0 if decision_period else NOMINAL_STEP_S


def integral_limit(gain: float, offset_limit: float = DEFAULT_OFFSET_LIMIT) -> float:
    """The bound (m) on I for which ``gain * I`` (m/s, ``gain`` in 1/s) stays within
    +-``offset_limit``."""
    if not (isfinite(gain) and gain > 0.0 and isfinite(offset_limit) and offset_limit > 0.0):
        raise ValueError(f"the speed integral's gain and offset limit must be finite numbers > 0, "
                         f"got {gain!r} and {offset_limit!r}")
    return offset_limit / gain


@dataclass(frozen=True)
class WindupDecay:
    """What the integral winds up after a change of the command decays once the hip has passed
    the new command. After a change, I integrates as without the rule (the windup buys a fast
    reach); the first time within ``seconds`` s of the change that the error turns against the
    change (v_d - v̄ < 0 after a step up, > 0 after a step down), I starts to decay toward the
    value it had at the change, with time constant ``tau`` s, while it goes on integrating;
    ``seconds`` s after the change the decay stops and I integrates as before. A walk at a
    constant command is the same walk bit for bit with and without the rule.

    Why: while the hip lags a new command, the integral winds up, and unwinding it takes
    seconds of overshoot; holding it during the lag (a ``band``) also loses the fast reach.
    The decay keeps the windup's fast reach and takes the overshoot out. ``at_start``: a
    walk's start counts as a change of the command up to v_d (from rest): every walk's first
    steps run slow, and what I winds up over them decays once the hip has passed v_d. Off, a
    walk is the same walk bit for bit as before the option existed (what each choice
    measured: docs/learning.md, 2026-11-27 (sixth) and 2026-11-28 (second)).

    ``disturbance`` (m/s): an error larger than it at a constant command (a push, a stumble)
    opens the window as a change its way does (v_d - v̄ > 0, the hip slowed: as a change up):
    what I winds up while the hip is off decays once the hip has passed the command. Its
    anchor is I as the disturbance is first seen; inside a window already open (a change,
    an earlier disturbance) the anchor is kept and the window starts again. None: no such
    rule, a walk the same bit for bit as before the option existed. Why: after a push the
    integral wound up to its bound while the hip was slow, and the overshoot it left lasted
    for seconds (docs/learning.md, 2026-12-07)."""

    seconds: float = 5.0
    tau: float = 1.0
    at_start: bool = False
    disturbance: float | None = None
    OPTIONAL_KEYS: ClassVar[tuple[str, ...]] = ("disturbance",)
    """A controller spec may leave these out (absent: None, the rule off, as in every spec written before it)."""

    def __post_init__(self) -> None:
        for name in ("seconds", "tau"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and isfinite(value) and value > 0.0):
                raise ValueError(f"the speed integral's windup decay {name} must be a finite number > 0 (s), "
                                 f"got {value!r}")
        if not isinstance(self.at_start, bool):
            raise ValueError(f"the speed integral's windup decay at_start must be True or False, got {self.at_start!r}")
        if self.disturbance is not None and not (isinstance(self.disturbance, (int, float))
                                                 and not isinstance(self.disturbance, bool)
                                                 and isfinite(self.disturbance) and self.disturbance > 0.0):
            raise ValueError("the speed integral's windup decay disturbance must be a finite number > 0 (m/s) or "
                             f"None, got {self.disturbance!r}")


@dataclass(frozen=True)
class IntegralFeedforward:
    """The integral's steady value per commanded speed: I walks to ``values[i]`` (m) at a
    constant command ``speeds[i]`` (m/s, increasing) on the nominal model; linear in between,
    the end values beyond the ends. With it, a change of the command from v to v' adds
    I*(v') - I*(v) to I (a feed-forward: what a model error added to I is kept), and with
    ``start`` a walk's integral starts at I*(v_d) instead of 0. The integral still
    integrates every error; without ``start``, a walk at a constant command is the same walk
    bit for bit.

    Why: a network trained with I as an input may need a different I at each speed to walk
    at its command, so after a change I has to wind from the old speed's steady value to the
    new one's through the error, and a walk that starts at I = 0 runs off its command for
    seconds (docs/learning.md, 2026-11-27 (seventh) and 2026-11-28 (second)).
    :func:`~rabbit_policy.evaluation.steady_integral.steady_integrals` measures a table; a
    controller spec records it."""

    speeds: tuple[float, ...]
    values: tuple[float, ...]
    start: bool = False

    def __post_init__(self) -> None:
        try:
            speeds, values = tuple(float(v) for v in self.speeds), tuple(float(v) for v in self.values)
        except (TypeError, ValueError):
            raise ValueError(f"the speed integral's feed-forward needs numbers, got {self.speeds!r} and "
                             f"{self.values!r}") from None
        if not (len(speeds) == len(values) >= 2 and all(isfinite(v) for v in speeds + values)
                and all(a < b for a, b in zip(speeds, speeds[1:]))):
            raise ValueError("the speed integral's feed-forward needs at least two finite (speed, value) pairs, "
                             f"the speeds increasing, got {self.speeds!r} and {self.values!r}")
        if not isinstance(self.start, bool):
            raise ValueError(f"the speed integral's feed-forward start must be True or False, got {self.start!r}")
        object.__setattr__(self, "speeds", speeds)
        object.__setattr__(self, "values", values)

    def at(self, speed: float) -> float:
        """I* (m) at the commanded ``speed`` (m/s): linear between the table's speeds, the end
        values beyond them."""
        speeds, values = self.speeds, self.values
        if speed <= speeds[0]:
            return values[0]
        if speed >= speeds[-1]:
            return values[-1]
        i = bisect_right(speeds, speed) - 1
        share = (speed - speeds[i]) / (speeds[i + 1] - speeds[i])
        return values[i] + share * (values[i + 1] - values[i])


@dataclass(frozen=True)
class IntegralConfig:
    """``limit``: the bound on I (m, anti-windup); ``dt``: s between decisions; ``gain``
    (1/s) with ``speed_range`` (m/s, low, high): I is also held where the commanded gait
    ``v_d + gain * I`` stays within the range (the library's speeds), so it never winds up
    into gaits the library does not have (None: no such gate, as in the memory of the
    policies trained before it); ``band`` (m/s): I integrates only while the error is
    smaller than it, |v_d - v̄| < band, and is held otherwise (None: always integrates);
    ``clip`` (m/s): the error integrated is clipped to +-clip, so a large error integrates
    at that rate and no faster (None: as it is); ``windup_decay``: after a change of the
    command, what I wound up decays once the hip has passed the new command
    (:class:`WindupDecay`; None: no decay); ``feedforward``: I moves by the difference of
    its steady values at a change of the command (and may start a walk at its steady value)
    (:class:`IntegralFeedforward`; None: moves only by integrating, starts at 0).

    Why the band (conditional integration) and the clip: a large error is a transient, a hip
    lagging a new command or a push, not the steady error an integral is for (docs/learning.md,
    2026-11-27 (fifth))."""

    limit: float
    dt: float
    gain: float = 0.0
    speed_range: tuple[float, float] | None = None
    band: float | None = None
    clip: float | None = None
    windup_decay: WindupDecay | None = None
    feedforward: IntegralFeedforward | None = None

    def __post_init__(self) -> None:
        if self.feedforward is not None and not isinstance(self.feedforward, IntegralFeedforward):
            raise ValueError(f"the speed integral's feed-forward must be an IntegralFeedforward or None, got "
                             f"{self.feedforward!r}")
        decay = self.windup_decay
        if decay is not None and not isinstance(decay, WindupDecay):
            raise ValueError(f"the speed integral's windup decay must be a WindupDecay or None, got {decay!r}")
        if decay is not None and not decay.tau >= self.dt:
            raise ValueError(f"the speed integral's windup decay tau must be at least dt ({self.dt:g} s), got "
                             f"{decay.tau!r}")
        if not (isfinite(self.gain) and self.gain >= 0.0):
            raise ValueError(f"the speed integral's gain must be a finite number >= 0 (1/s), got {self.gain!r}")
        for name in ("limit", "dt"):
            value = getattr(self, name)
            if not (isfinite(value) and value > 0.0):
                raise ValueError(f"the speed integral's {name} must be a finite number > 0, got {value!r}")
        for name in ("band", "clip"):
            value = getattr(self, name)
            if value is not None and not (isfinite(value) and value > 0.0):
                raise ValueError(f"the speed integral's {name} must be a finite number > 0 (m/s) or None, got {value!r}")
        if self.speed_range is not None:
            low, high = self.speed_range
            if not (isfinite(low) and isfinite(high) and low < high and isfinite(self.gain) and self.gain > 0.0):
                raise ValueError(f"the speed integral's speed range needs low < high (m/s) and a gain > 0, got "
                                 f"{self.speed_range!r} and {self.gain!r}")

    def to_dict(self) -> dict:
        """The fields as plain data (the rules as dicts), as a checkpoint's ``memory`` stores them."""
        return asdict(self)

    @classmethod
    def from_dict(cls, info: dict) -> "IntegralConfig":
        """The configuration :meth:`to_dict` wrote (a checkpoint's JSON-like info: the range a
        list, the rules dicts); ``ValueError`` for a field it does not have or a bad value."""
        info = dict(info)
        for name, kind in (("windup_decay", WindupDecay), ("feedforward", IntegralFeedforward)):
            if isinstance(info.get(name), dict):
                try:
                    info[name] = kind(**info[name])
                except TypeError as exc:
                    raise ValueError(f"the speed integral's {name.replace('_', ' ')}: {exc}") from None
        if info.get("speed_range") is not None:
            info["speed_range"] = tuple(float(v) for v in info["speed_range"])
        try:
            return cls(**info)
        except TypeError as exc:
            raise ValueError(f"the speed integral: {exc}") from None


class SpeedIntegral:
    """I, updated once per decision (see the module docstring)."""

    def __init__(self, config: IntegralConfig) -> None:
        self.config = config
        decay = config.windup_decay
        self._window = max(1, round(decay.seconds / config.dt)) if decay is not None else 0  # decisions
        self._keep = 1.0 - config.dt / decay.tau if decay is not None else 1.0  # per decision while decaying
        self.reset()

    def reset(self) -> None:
        """A new walk: I = 0, no command change seen."""
        self.value = 0.0
        self._last_command: float | None = None
        self._anchor = 0.0  # I at the last change
        self._direction = 0.0  # the last change's sign (m/s)
        self._looking = 0  # decisions left to look for the hip passing the new command
        self._since = 0  # decisions since the last change
        self._decaying = False

    def update(self, error: float, desired_speed: float) -> float:
        """Add one decision's mean speed error (m/s, over its ``dt``) and return I (m);
        ``desired_speed`` (m/s, v_d) places the range gate and, with a windup decay or a
        feed-forward, marks the start and command changes."""
        previous, self._last_command = self._last_command, desired_speed
        changed = previous is not None and desired_speed != previous
        feedforward = self.config.feedforward
        if feedforward is not None and previous is None and feedforward.start:  # a walk's first decision
            self.value = self._bounded(feedforward.at(desired_speed), desired_speed)
        elif feedforward is not None and changed:
            self.value = self._bounded(self.value + feedforward.at(desired_speed) - feedforward.at(previous),
                                       desired_speed)
        if self.config.windup_decay is None:
            return self._integrate(error, desired_speed)
        if previous is None and self.config.windup_decay.at_start:  # a walk's start: a change up to v_d
            self._anchor = self.value
            self._looking, self._direction, self._decaying, self._since = self._window, desired_speed, False, 0
        if changed:
            if not self._decaying:  # (a change during a decay keeps the value it decays toward)
                self._anchor = self.value
            self._looking, self._direction, self._decaying, self._since = self._window, desired_speed - previous, False, 0
        elif self._disturbed(previous, error):  # as a change its way
            if not (self._looking > 0 or self._decaying):  # no window open: anchored here (else the open one's anchor)
                self._anchor = self.value
            self._looking, self._direction, self._decaying, self._since = self._window, float(error), False, 0
        self._since += 1
        if self._since > self._window:
            self._decaying = False
        value = self._integrate(error, desired_speed)
        if self._looking > 0:
            self._looking -= 1
            if self._direction * error < 0.0:  # the hip has passed the new command
                self._looking, self._decaying = 0, True
        if self._decaying:
            self.value = value = self._anchor + (value - self._anchor) * self._keep
        return value

    def _disturbed(self, previous: float | None, error: float) -> bool:
        """At a constant command (not a walk's first decision), an error beyond the windup
        decay's ``disturbance``."""
        limit = self.config.windup_decay.disturbance
        return limit is not None and previous is not None and abs(error) > limit

    def _integrate(self, error: float, desired_speed: float) -> float:
        """The integral's step without the windup decay (band, clip, range gate, bound)."""
        config = self.config
        if config.band is not None and not abs(error) < config.band:
            return self.value  # a transient, not a steady error: held
        if config.clip is not None:
            error = min(max(float(error), -config.clip), config.clip)
        self.value = self._bounded(self.value + float(error) * config.dt, desired_speed)
        return self.value

    def _bounded(self, value: float, desired_speed: float) -> float:
        """``value`` (m) within the range gate at ``desired_speed`` (m/s) and the bound."""
        config = self.config
        if config.speed_range is not None:
            low, high = config.speed_range
            value = min((high - desired_speed) / config.gain, max((low - desired_speed) / config.gain, value))
        return min(config.limit, max(-config.limit, value))
