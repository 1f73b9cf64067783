"""Which states go out together on ``/sim/state_batch``, ROS-free: :class:`StateBatcher`.

Observers that need every state but not each one at once (the policy's averages, run_stack's
supervisor, a plot) take the states in batches instead of 1000 messages a second. A batch
goes out on the state that makes it ``batch_ticks`` long, on a state whose stamp is a
multiple of ``batch_ticks`` ticks (so batches keep to one grid from each placement), on a
state a policy decides on (the period it announces on ``/hzd/gait_timing``:
:class:`rabbit_msgs_py.decision_ticks.PeriodicDecisions`, the rule the policy and a
controller holding its reply follow; a lockstep controller waits for that decision, so its
last sample must not wait in a batch), on a state sent again or placed (a stamp not after
the last one), and (the node says so) when the physics halts or pauses. Stamps are ns of
sim time.
"""

from __future__ import annotations

import array
from typing import Sequence

from rabbit_msgs_py.decision_ticks import TICK_NS, PeriodicDecisions


class StateBatcher:
    """The states not yet sent on ``/sim/state_batch`` and the rule of when they go."""

    def __init__(self, batch_ticks: int, tick: int = TICK_NS) -> None:
        if isinstance(batch_ticks, bool) or not isinstance(batch_ticks, int) or batch_ticks < 1:
            raise ValueError(f"batch_ticks must be a whole number >= 1, got {batch_ticks!r}")
        self.size, self.tick = batch_ticks, tick
        self.rows = array.array("d")
        self.count = 0
        self._decisions: PeriodicDecisions | None = None
        self._last: int | None = None  # the newest stamp added

    def follow_decisions(self, period: int) -> None:
        """A policy decides every ``period`` ticks (0: once per step, none to follow): each
        state it decides on ends a batch, from the next one on."""
        if self._decisions is not None and self._decisions.period == period * self.tick:
            return
        self._decisions = PeriodicDecisions(period, self.tick) if period else None
        if self._decisions is not None and self._last is not None:
            self._decisions.join(self._last)

    def add(self, stamp: int, position: Sequence[float], velocity: Sequence[float],
            effort: Sequence[float]) -> bool:
        """Add a state as it is published; True when the batch is to go out now (:meth:`take`)."""
        again = self._last is not None and stamp <= self._last
        due = self._decisions.due(stamp) if self._decisions is not None else False
        self._last = stamp
        rows = self.rows
        rows.append(stamp)
        rows.extend(position)
        rows.extend(velocity)
        rows.extend(effort)
        self.count += 1
        return again or due or self.count >= self.size or stamp % (self.size * self.tick) == 0

    def take(self) -> tuple[array.array, int]:
        """The states waiting (float64 rows) and how many; the batch starts empty again."""
        rows, count = self.rows, self.count
        self.rows, self.count = array.array("d"), 0
        return rows, count
