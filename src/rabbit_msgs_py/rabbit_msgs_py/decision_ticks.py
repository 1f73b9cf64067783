"""When a policy decides, one type and one rule for everyone.

:class:`DecisionTiming` says when (the policy's own timing, once per step, or every N ticks),
parsed, formatted and checked here only: from the command line (``own``, ``step`` or N; the
older ``-1`` and ``0`` too), from a node parameter (``-1``, ``0``, N), and on the wire
(``/hzd/gait_timing``: ``next_step`` or ``at_once:N``).

:class:`PeriodicDecisions` says which states a policy deciding every N ticks decides on: the
one rule that the policy's decision clock (``rabbit_policy.runtime.decision_clock``) and a
controller holding its reply for a due decision (``hzd_controller_node`` with
``decision_sync``) both follow.

Stamps are integers in any unit (the ROS-free loop: ticks; the nodes: ns of sim time),
``tick`` the physics step in that unit. The placed state (stamp 0) is never due; a state is
due when its stamp reaches the next multiple of ``period`` ticks since the placement; the
next due stamp is then the first multiple after it (a state missed does not make two due).
A stamp at or before 0, or older than the last one seen, is a new placement; the last one
seen again (a state re-sent) is not due a second time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

TICK_NS = 1_000_000
"""The simulation's step in ns of sim time (the model's 1 ms timestep: one control tick)."""

GAIT_TIMINGS = ("next_step", "at_once")
"""How a gait applies, as ``/hzd/gait_timing`` says: at the next touchdown, or at once."""


@dataclass(frozen=True)
class DecisionTiming:
    """When a policy decides: ``ticks`` None = as the policy was made (classic every 20 ticks;
    a learned policy as trained), 0 = once per step (at the touchdown, the gait queued to the
    next one), N = every N ticks of 1 ms (the gait applied at once, blended in)."""

    ticks: int | None = None

    def __post_init__(self) -> None:
        if self.ticks is not None and (isinstance(self.ticks, bool) or not isinstance(self.ticks, int)
                                       or self.ticks < 0):
            raise ValueError(f"a decision timing is own, step or a whole number of ticks >= 1, got {self.ticks!r}")

    @classmethod
    def parse(cls, text: str | int) -> "DecisionTiming":
        """The command line's ``own``, ``step`` or N (ticks); ``-1`` and ``0`` are the older
        spellings of own and step (and a node parameter's). ``ValueError`` otherwise."""
        value = str(text).strip().lower()
        if value in ("own", "-1"):
            return cls(None)
        if value in ("step", "0"):
            return cls(0)
        if value.isdigit():
            return cls(int(value))
        raise ValueError(f"a decision timing is own, step or a whole number of ticks >= 1, got {text!r}")

    @property
    def param(self) -> int:
        """As a node parameter: -1 own, 0 once per step, N."""
        return -1 if self.ticks is None else self.ticks

    def resolve(self, own: int) -> int:
        """Ticks between decisions (0: once per step), ``own`` being the policy's own."""
        return own if self.ticks is None else self.ticks

    def __str__(self) -> str:
        return "own" if self.ticks is None else "step" if self.ticks == 0 else str(self.ticks)


def check_ticks(value: int, what: str = "the decision period", minimum: int = 1) -> int:
    """``value`` back if it is a whole number of ticks >= ``minimum`` (0: once per step where
    that is allowed), else ``ValueError`` naming ``what``: the one check of a tick count that
    the periodic policy, the decision clock and this module's schedules share."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{what} must be a whole number of ticks >= {minimum}, got {value!r}")
    return value


def decision_ticks(value: int) -> int:
    """A concrete timing in ticks, as a training environment and its episodes take it (0: one
    env step per walking step, N: every N ticks; not "own": an environment has no policy of
    its own to ask): ``value`` back, or ``ValueError`` with :class:`DecisionTiming`'s words."""
    timing = DecisionTiming(value)
    if timing.ticks is None:
        raise ValueError("a decision timing in ticks is step (0) or a whole number of ticks >= 1, got own")
    return timing.ticks


OWN = DecisionTiming(None)
PER_STEP = DecisionTiming(0)


CONTROLLER_SETTINGS = ("kp", "torque_limit", "touchdown_min_phase", "touchdown_height", "min_step_length",
                       "hip_coefficient_range", "knee_coefficient_range", "max_kd", "blend_phase",
                       "within_step_blend", "within_step_until", "min_phase_rate")
"""The 1 kHz controller's settings a policy announces on ``/hzd/gait_timing`` (its spec's
``controller``: every ``ControllerConfig`` field but the robot model's geometry and tick)."""
SIGNATURE_FIELD = "signed="
"""The last field of a signed announcement: ``signed=<policy instance>:<tag>``
(``rabbit_msgs_py.pairing.PairingKey.sign_settings``)."""


def _value_text(value) -> str:
    if isinstance(value, (tuple, list)):
        return ",".join(repr(float(v)) for v in value)
    return repr(float(value))


def gait_timing(period: int, settings: dict | None = None) -> str:
    """``/hzd/gait_timing`` for a policy deciding every ``period`` ticks (0: once per step):
    ``next_step``, or ``at_once:N``, which also tells a controller holding its reply for a
    due decision (``decision_sync``) which states are due; then the controller settings the
    policy needs (its spec's), ``name=value`` each, a range as ``name=low,high``
    (:data:`CONTROLLER_SETTINGS`)."""
    text = f"at_once:{period}" if period else "next_step"
    return text + "".join(f" {name}={_value_text(value)}" for name, value in (settings or {}).items())


def timing_settings(text: str) -> dict:
    """The controller settings a ``/hzd/gait_timing`` announces ({} if none; a range as a
    tuple of two floats; a signature field aside); ``ValueError`` for a name not in
    :data:`CONTROLLER_SETTINGS` or a value that is not finite. Whether a value is one the
    controller can run with is the controller's to say (``ControllerConfig``)."""
    settings: dict = {}
    for part in text.split()[1:]:
        if part.startswith(SIGNATURE_FIELD):
            continue
        name, _, value = part.partition("=")
        try:
            numbers = tuple(float(v) for v in value.split(","))
        except ValueError:
            numbers = (math.nan,)
        if name not in CONTROLLER_SETTINGS or not all(math.isfinite(v) for v in numbers) or len(numbers) > 2:
            raise ValueError(f"a setting is one of {', '.join(CONTROLLER_SETTINGS)} = a finite number (a range: "
                             f"low,high), got {part!r}")
        ranged = name.endswith("_range")
        if ranged != (len(numbers) == 2):
            raise ValueError(f"{name} is {'a range low,high' if ranged else 'one number'}, got {part!r}")
        settings[name] = numbers if ranged else numbers[0]
    return settings


def parse_gait_timing(text: str) -> tuple[str, int]:
    """``/hzd/gait_timing``: ``next_step`` -> ("next_step", 0), ``at_once:N`` -> ("at_once", N)
    (``at_once`` alone: 0, no period), settings after it aside (:func:`timing_settings`);
    ``ValueError`` for anything else."""
    timing, _, period = (text.split() or [""])[0].partition(":")
    if timing not in GAIT_TIMINGS or (period and (timing != "at_once" or not period.isdigit() or int(period) < 1)):
        raise ValueError(f"not one of {GAIT_TIMINGS}, or at_once:N with N >= 1 ticks")
    return timing, int(period) if period else 0


def precedes_decision(stamp: int, period: int, tick: int = TICK_NS) -> bool:
    """Is the state at ``stamp`` the one before a decision of a policy deciding every
    ``period`` ticks (the state whose controller phase that decision reads: the next stamp is
    a multiple of the period since the placement)? Always true for ``period`` 0 (once per
    step, or not known): every state may be."""
    return not period or (stamp + tick) % (period * tick) == 0


class PeriodicDecisions:
    """See the module docstring."""

    def __init__(self, period: int, tick: int = 1) -> None:
        check_ticks(period)
        if not (isinstance(tick, int) and tick >= 1):
            raise ValueError(f"tick must be a whole number >= 1 stamp unit, got {tick!r}")
        self.period = period * tick  # in stamp units
        self.reset()

    def reset(self) -> None:
        """The robot was placed again."""
        self._next = self.period
        self._last: int | None = None

    def join(self, stamp: int) -> None:
        """Start following mid-run, the state at ``stamp`` already seen: the next due state
        is the first multiple of the period after it (what the policy's clock, following
        from the placement, decides on next)."""
        self._last = stamp
        self._next = self.period * (stamp // self.period + 1) if stamp > 0 else self.period

    @property
    def next_due(self) -> int:
        """The stamp from which the next state is due."""
        return self._next

    def skip_to(self, stamp: int) -> None:
        """States up to ``stamp`` were seen and none was due (``stamp`` < :attr:`next_due`,
        after the last seen): as :meth:`due` on each of them, at once."""
        if not ((self._last is None or stamp > self._last) and 0 < stamp < self._next):
            raise ValueError(f"stamp {stamp} cannot be skipped to (last {self._last}, next due {self._next})")
        self._last = stamp

    def due(self, stamp: int) -> bool:
        """True if the policy decides on the state at ``stamp`` (see the module docstring)."""
        if self._last is not None and stamp == self._last:
            return False
        if stamp <= 0 or (self._last is not None and stamp < self._last):
            self.reset()
            if stamp <= 0:
                return False
        self._last = stamp
        if stamp < self._next:
            return False
        self._next += self.period * (1 + (stamp - self._next) // self.period)
        return True
