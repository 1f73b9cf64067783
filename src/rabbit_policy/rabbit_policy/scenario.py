"""What an experiment commands, ROS-free: a speed schedule and pushes on the torso, and
their text forms (``"0:0.8,10:1.2"``, ``"2:60:0.1,4:-80:0.2"``) used by the scripts.
Shared by the node stack (:mod:`.stack`) and the fast path (:mod:`.policy_walk`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

Schedule = tuple[tuple[float, float], ...]  # (start time s, commanded speed m/s)


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


def validate_schedule(schedule: Sequence[tuple[float, float]]) -> None:
    """Raise ``ValueError`` unless the schedule starts at t = 0 and its times increase."""
    if not schedule or schedule[0][0] != 0.0:
        raise ValueError("the speed schedule must start at t = 0")
    times = [t for t, _ in schedule]
    if any(b <= a for a, b in zip(times, times[1:])):
        raise ValueError("speed schedule times must increase")


def parse_schedule(text: str) -> Schedule:
    """``"0:0.8,10:1.2"`` -> ((0.0, 0.8), (10.0, 1.2)); raises ``ValueError``."""
    pairs = []
    for item in text.split(","):
        try:
            t, v = (float(x) for x in item.split(":"))
        except ValueError:
            raise ValueError(f"speed schedule entries are time:speed, got {item!r}") from None
        if not (math.isfinite(t) and math.isfinite(v)) or t < 0:
            raise ValueError(f"bad speed schedule entry {item!r}")
        pairs.append((t, v))
    return tuple(pairs)


def parse_pushes(text: str) -> tuple[Push, ...]:
    """``"2:60:0.1,4:-80:0.2"`` -> pushes (time s : force N : duration s), by time."""
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
