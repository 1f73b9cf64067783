"""Which states a policy deciding every N ticks decides on: the one rule that the policy's
decision clock (``rabbit_policy.runtime.decision_clock``) and a controller holding its reply
for a due decision (``hzd_controller_node`` with ``decision_sync``) both follow.

Stamps are integers in any unit (the ROS-free loop: ticks; the nodes: ns of sim time),
``tick`` the physics step in that unit. The placed state (stamp 0) is never due; a state is
due when its stamp reaches the next multiple of ``period`` ticks since the placement; the
next due stamp is then the first multiple after it (a state missed does not make two due).
A stamp at or before 0, or older than the last one seen, is a new placement; the last one
seen again (a state re-sent) is not due a second time.
"""

from __future__ import annotations

TICK_NS = 1_000_000
"""The simulation's step in ns of sim time (the model's 1 ms timestep: one control tick)."""


class PeriodicDecisions:
    """See the module docstring."""

    def __init__(self, period: int, tick: int = 1) -> None:
        if not (isinstance(period, int) and period >= 1):
            raise ValueError(f"the decision period must be a whole number of ticks >= 1, got {period!r}")
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
