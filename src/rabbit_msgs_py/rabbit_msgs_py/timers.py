"""Timers that run on the steady wall clock whatever ``use_sim_time`` says (needs rclpy).

A node's own clock follows ``/clock`` once ``use_sim_time`` is true, and sim time stands
still until the simulator runs. Every timer of this project paces or supervises the
simulation from outside it (the solo check before a node starts, the simulator's own
1 ms pacing, re-sends and watchdogs, a log flushed once a second), so all of them run on
the steady clock: a stack started with ``-p use_sim_time:=true`` on every node starts and
walks like one without it. Sim time reaches the nodes in the messages' stamps.
"""

from __future__ import annotations

from typing import Callable


def wall_timer(node, period: float, callback: Callable[[], None]):
    """``node.create_timer`` on the steady clock: ``callback`` every ``period`` s of wall time."""
    from rclpy.clock import Clock, ClockType

    return node.create_timer(period, callback, clock=Clock(clock_type=ClockType.STEADY_TIME))


class OneShot:
    """A steady-clock timer that calls ``callback`` once, ``wait`` s after :meth:`arm` (an
    rclpy timer repeats: this one cancels itself before it calls back); idle until armed."""

    def __init__(self, node, callback: Callable[[], None]) -> None:
        self._callback = callback
        self._timer = wall_timer(node, 0.001, self._fire)
        self._timer.cancel()

    def arm(self, wait: float) -> None:
        """Call back ``wait`` s (wall) from now, unless armed already."""
        if self._timer.is_canceled():
            self._timer.timer_period_ns = max(1000, int(wait * 1e9))  # (rcl wants a period > 0)
            self._timer.reset()

    def cancel(self) -> None:
        self._timer.cancel()

    def _fire(self) -> None:
        self._timer.cancel()
        self._callback()
