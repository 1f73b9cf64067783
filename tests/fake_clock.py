"""A settable wall clock for the ROS-free rules that read the time (the simulator's stepping
rules and driver, the controller's driver)."""

from __future__ import annotations


class FakeClock:
    """A wall clock (s) that moves only when a test sets ``now``."""

    def __init__(self, now: float = 100.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now
