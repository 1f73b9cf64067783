"""The integral of the speed error with anti-windup: the one implementation of that rule.

``I = clamp(I + (v_d - v̄) dt, -limit, +limit)`` per decision (m: m/s times s), with
``v_d - v̄`` the observation's mean speed error and ``dt`` the time between decisions;
conditional integration: at the bound the sum stops growing, so it unwinds at once when the
error turns (with a ``band``, it also integrates only errors smaller than the band; with a
``clip``, the error clipped; with a :class:`SteadyGate`, for a few seconds after each change of
the command it integrates only an error that has stopped moving). Where I offsets the library's gait (below), it is also held
where that gait ``v_d + gain * I`` would leave the library's speeds (:class:`IntegralConfig`'s
``speed_range``): beyond them ``interpolate`` clamps, so anything integrated there is
windup. Measured on checks 2, 3 and 5 (docs/learning.md, "the range gate"), that gate took classic
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

from collections import deque
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
class SteadyGate:
    """For ``seconds`` s after each change of the command, the integral integrates only a
    *steady* error: one that moved by less than ``delta`` m/s over the last ``window`` s
    (about a step); elsewhere (a walk's start, pushes, model errors at a constant command) it
    integrates as without the gate.

    Why: after a change the error is the hip's lag behind the new command, a transient that
    ends on its own. Integrated, it wound the shipped policy's offset up by as much as 0.12 m/s,
    which then took about 10 s to unwind (34 of 60 changes settled within 0.03 m/s 5-10 s after
    the change; classic 57). A band (hold while the error is large, ``IntegralConfig.band``)
    removed the overshoot but also every steady error larger than itself, and lost the 3 ms
    torque delay at 1.3 m/s; this gate leaves every walk at a constant command bit for bit as
    it was, so the model errors and push margins cannot change, and settled 56 of the 60
    (docs/learning.md, 2026-11-27 (sixth))."""

    seconds: float = 5.0
    delta: float = 0.03
    window: float = 0.5

    def __post_init__(self) -> None:
        for name in ("seconds", "delta", "window"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and isfinite(value) and value > 0.0):
                raise ValueError(f"the speed integral's steady gate {name} must be a finite number > 0, got {value!r}")

    def decisions(self, dt: float) -> tuple[int, int]:
        """(decisions the gate stays shut after a change, decisions back the error is compared
        with), each at least 1, for decisions every ``dt`` s."""
        return max(1, round(self.seconds / dt)), max(1, round(self.window / dt))


@dataclass(frozen=True)
class IntegralConfig:
    """``limit``: the bound on I (m, anti-windup); ``dt``: s between decisions; ``gain``
    (1/s) with ``speed_range`` (m/s, low, high): I is also held where the commanded gait
    ``v_d + gain * I`` stays within the range (the library's speeds), so it never winds up
    into gaits the library does not have (None: no such gate, as in the memory of the
    policies trained before it); ``band`` (m/s): I integrates only while the error is
    smaller than it, |v_d - v̄| < band, and is held otherwise (None: always integrates);
    ``clip`` (m/s): the error integrated is clipped to +-clip, so a large error integrates
    at that rate and no faster (None: as it is); ``steady_gate``: after a change of the
    command, only a steady error integrates (:class:`SteadyGate`; None: no gate).

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
    steady_gate: SteadyGate | None = None

    def __post_init__(self) -> None:
        if self.steady_gate is not None and not isinstance(self.steady_gate, SteadyGate):
            raise ValueError(f"the speed integral's steady gate must be a SteadyGate or None, got {self.steady_gate!r}")
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
        gate = config.steady_gate
        self._shut_for, back = gate.decisions(config.dt) if gate is not None else (0, 0)
        self._errors: deque = deque(maxlen=back + 1)  # the errors of the last ``back`` decisions and this one
        self.reset()

    def reset(self) -> None:
        """A new walk: I = 0, no command change seen."""
        self.value = 0.0
        self._errors.clear()
        self._last_command: float | None = None
        self._shut = 0  # decisions the steady gate stays shut

    def _gate_holds(self, error: float, desired_speed: float) -> bool:
        """The steady gate: True while it is shut (after a command change) and the error is not
        steady (moved by ``delta`` or more over the window, or no error known)."""
        gate = self.config.steady_gate
        if gate is None:
            return False
        self._errors.append(float(error))
        if self._last_command is not None and desired_speed != self._last_command:
            self._shut = self._shut_for
        self._last_command = desired_speed
        if self._shut == 0:
            return False
        self._shut -= 1
        full = len(self._errors) == self._errors.maxlen
        return not (full and abs(error - self._errors[0]) < gate.delta)

    def update(self, error: float, desired_speed: float) -> float:
        """Add one decision's mean speed error (m/s, over its ``dt``) and return I (m);
        ``desired_speed`` (m/s, v_d) places the range gate and, with a steady gate, marks a
        command change."""
        config = self.config
        if self._gate_holds(error, desired_speed):
            return self.value  # the lag behind a new command, not a steady error: held
        if config.band is not None and not abs(error) < config.band:
            return self.value  # a transient, not a steady error: held
        if config.clip is not None:
            error = min(max(float(error), -config.clip), config.clip)
        value = self.value + float(error) * config.dt
        if config.speed_range is not None:
            low, high = config.speed_range
            value = min((high - desired_speed) / config.gain, max((low - desired_speed) / config.gain, value))
        self.value = min(config.limit, max(-config.limit, value))
        return self.value
