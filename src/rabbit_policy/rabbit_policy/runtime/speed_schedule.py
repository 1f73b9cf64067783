"""When a speed schedule's changes apply, in state stamps (ns of sim time): one rule for the
ROS-free loop (:class:`~rabbit_policy.experiment.loop.ClosedLoop`) and ``policy_node``
(parameter ``speed_schedule``), so a multi-process lockstep run commands each change at the
very state walk.py does, whatever the message timing.

A change at ``t`` s applies from the first state whose stamp is at least ``t`` (1 ns of
slack for ``t`` given in decimal seconds): that state's hip speed is the first sample taken
under the new command."""

from __future__ import annotations

from typing import Sequence


def stamp_of(seconds: float) -> int:
    """Seconds of sim time -> the nearest ns stamp."""
    return round(seconds * 1e9)


class SpeedSchedule:
    """The changes after the start, ``((t, speed), ...)`` (s, m/s, times increasing), stepped
    through by state stamps; :meth:`restart` when the robot is placed again."""

    def __init__(self, changes: Sequence[tuple[float, float]]) -> None:
        self.changes = tuple((stamp_of(t), float(v)) for t, v in changes)
        self._next = 0

    def restart(self) -> None:
        """The robot was placed again (t = 0): the schedule starts over."""
        self._next = 0

    @property
    def next_stamp(self) -> int | None:
        """The stamp (ns) of the next change, None when all have applied."""
        return self.changes[self._next][0] if self._next < len(self.changes) else None

    def due(self, stamp: int) -> float | None:
        """The speed commanded from the state at ``stamp`` (ns) on, if a change falls due
        there (the last, if several), else None."""
        speed = None
        while self._next < len(self.changes) and stamp >= self.changes[self._next][0] - 1:
            speed = self.changes[self._next][1]
            self._next += 1
        return speed
