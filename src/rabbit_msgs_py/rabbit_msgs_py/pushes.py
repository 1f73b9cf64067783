"""Pushes on the torso and their text form, shared by the simulator (``sim_node``'s
``push_schedule`` parameter), the launch scripts (``run_stack.py --push``) and the
ROS-free fast path: ``"2:60:0.1,4:-80:0.2"`` = at 2 s sim time +60 N for 0.1 s, at 4 s
-80 N for 0.2 s (force along world x, + forward, at the torso's centre of mass)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Push:
    """A push on the torso: at sim time ``time`` (s), force ``force_x`` (N, world x,
    + forward) held for ``duration`` s."""

    time: float
    force_x: float
    duration: float

    @property
    def impulse(self) -> float:
        """N s."""
        return self.force_x * self.duration


def parse_pushes(text: str) -> tuple[Push, ...]:
    """``"2:60:0.1,4:-80:0.2"`` -> pushes (time s : force N : duration s), by time;
    ``""`` -> no pushes. Raises ``ValueError`` naming the bad entry."""
    if not text.strip():
        return ()
    pushes = []
    for item in text.split(","):
        try:
            t, f, d = (float(x) for x in item.split(":"))
        except ValueError:
            raise ValueError(f"pushes are time:force:duration, got {item!r}") from None
        if not all(math.isfinite(x) for x in (t, f, d)) or t < 0 or d <= 0:
            raise ValueError(f"bad push {item!r}")
        pushes.append(Push(t, f, d))
    return tuple(sorted(pushes, key=lambda p: p.time))


def format_pushes(pushes: tuple[Push, ...] | list[Push]) -> str:
    """The inverse of :func:`parse_pushes` (exact: floats in ``repr`` form)."""
    return ",".join(f"{p.time!r}:{p.force_x!r}:{p.duration!r}" for p in pushes)
