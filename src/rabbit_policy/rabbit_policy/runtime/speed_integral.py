"""The integral of the speed error with anti-windup: the one implementation of that rule.

``I = clamp(I + (v_d - v̄) dt, -limit, +limit)`` per decision (m: m/s times s), with
``v_d - v̄`` the observation's mean speed error and ``dt`` the time between decisions;
conditional integration: at the bound the sum stops growing, so it unwinds at once when the
error turns (with a ``band``, it also integrates only errors smaller than the band; with a
``clip``, the error clipped; with a :class:`WindupDecay`, what it wound up after a change of
the command decays once the hip has passed the new command). Where I offsets the library's
gait (below), it is also held where that gait ``v_d + gain * I`` would leave the library's
speeds (:class:`IntegralConfig`'s ``speed_range``): beyond them ``interpolate`` clamps, so
anything integrated there is windup. Measured on checks 2, 3 and 5 (docs/learning.md, "the range gate"), that gate took classic
+ integral 0.3 from 91 to 95 of 100 random sequences and from 50 to 52 of 72 speed changes,
the model errors unchanged. Its users:

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
from dataclasses import dataclass
from math import isfinite

NOMINAL_STEP_S = 0.6
"""A walking step's duration (s): the integral's dt for decisions once per step."""

DEFAULT_OFFSET_LIMIT = 0.2
"""Bound (m/s) on the integral's speed offset on the library: beyond it the library's
fastest gaits walk *slower* on the ``drives`` model (measured: the 1.45-1.5 m/s gaits walk
0.87 m/s there, the 1.3 m/s one 1.18), and a larger offset winds up into them."""


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

    Why: the shipped policy's integral wound up by as much as 0.13 m/s of offset while the hip
    lagged a new command and then took about 10 s to unwind: 34 of 60 random changes settled
    within 0.03 m/s 5-10 s after the change (classic 57). Holding I during the lag (a band, or a
    gate that integrates only a steady error) removed the overshoot but also the fast reach: 49
    of 72 ordered changes within 4 s, the network without a rule 68. With this rule (5 s, 1 s):
    55 of the 60 and 67 of the 72, and 183 of 200 other changes (docs/learning.md, 2026-11-27
    (sixth)); the learned policy ships with it. A decay that lasts until the next
    change settles fewer (48): the new speed's own steady error is then never integrated fully.

    ``at_start``: a walk's start counts as a change of the command up to v_d (from rest), so
    what I winds up over the first steps decays toward its value at the start once the hip has
    passed v_d. Every walk's first steps run slow (the robot starts on its gait with the hip at
    v_d, and the step after slows; classic at 0.8 m/s: 0.586 m/s), I wound up over them, and the
    shipped network then ran fast for seconds: 3-6 s after the start +0.070 m/s at 0.8, and a
    change of the command 6-7 s after the start carried the excess to the new speed. With this
    and the feed-forward's start (:class:`IntegralFeedforward`), 3-6 s after the start is within
    0.03 m/s at 17 of 17 speeds from 0.7 to 1.5 (without, 11), and 100 of the first 100 changes
    of a settling seed settle (without, 96) (docs/learning.md, 2026-11-28 (second)). Off, a walk
    is the same walk bit for bit as before the option existed."""

    seconds: float = 5.0
    tau: float = 1.0
    at_start: bool = False

    def __post_init__(self) -> None:
        for name in ("seconds", "tau"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and isfinite(value) and value > 0.0):
                raise ValueError(f"the speed integral's windup decay {name} must be a finite number > 0 (s), "
                                 f"got {value!r}")
        if not isinstance(self.at_start, bool):
            raise ValueError(f"the speed integral's windup decay at_start must be True or False, got {self.at_start!r}")


@dataclass(frozen=True)
class IntegralFeedforward:
    """The integral's steady value per commanded speed: I walks to ``values[i]`` (m) at a
    constant command ``speeds[i]`` (m/s, increasing) on the nominal model; linear in between,
    the end values beyond the ends. With it, a change of the command from v to v' adds
    I*(v') - I*(v) to I (a feed-forward: what a model error added to I is kept), and with
    ``start`` a walk's integral starts at I*(v_d) instead of 0. The integral still
    integrates every error; without ``start``, a walk at a constant command is the same walk
    bit for bit.

    Why: the shipped network needs I between -0.25 and +0.07 to walk at its command (it
    walks fast with I = 0 at most speeds), so after a change I has to wind from the old
    speed's steady value to the new one's through the error, and a walk that starts at I = 0
    is fast for several seconds. At changes the shift settled 58 of 60 random changes (without
    it 55), the ordered changes as fast as before; the start moved more walks within 0.03 m/s
    over 3-6 s (24 of 33 speeds, without 14) but took the walk at 1.3 m/s to where check 6's
    return map (the integral frozen) is unstable, so it is off by default (docs/learning.md,
    2026-11-27 (seventh)). Since 2026-11-28 (second) the shipped policy starts with it together
    with :class:`WindupDecay`'s ``at_start`` (check 6: max |lambda| 0.85). :func:`~rabbit_policy.evaluation.steady_integral.steady_integrals`
    measures a table; ``ship_policy.py --integral-feedforward`` records it."""

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

    Why the band (conditional integration): a large error is a transient, a hip lagging a
    new command or a push, not the steady error an integral is for. Integrated, it wound
    the shipped policy's offset up to 0.12 m/s after a speed change, which then took about
    10 s to unwind: 34 of 60 changes settled within 0.03 m/s, classic 57. Held while the
    error is 0.1 m/s or more, 57; clipped to 0.05 m/s, 56 (docs/learning.md, 2026-11-27
    (fifth)). Neither is shipped yet: each costs the shipped network something it won with
    the windup (the same section)."""

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
