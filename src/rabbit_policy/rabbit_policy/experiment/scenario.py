"""What an experiment commands, ROS-free: a speed schedule and pushes on the torso, and
their text forms (``"0:0.8,10:1.2"``, ``"2:60:0.1,4:-80:0.2"``) used by the scripts.
Shared by the node stack (:mod:`.stack`) and the fast path (:mod:`.policy_walk`); pushes
live in :mod:`rabbit_msgs_py.pushes` because the simulator node reads them too."""

from __future__ import annotations

import math
from typing import Sequence

from rabbit_msgs_py.pushes import Push, format_pushes, parse_pushes

__all__ = ["Push", "Schedule", "format_pushes", "parse_pushes", "parse_schedule", "validate_schedule"]

Schedule = tuple[tuple[float, float], ...]  # (start time s, commanded speed m/s)


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
