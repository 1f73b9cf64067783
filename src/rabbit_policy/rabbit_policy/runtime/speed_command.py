"""The commanded speed: one rule on every path. A command outside [low, high] (by default
:data:`COMMAND_RANGE`, the gait library's 0.7-1.5 m/s, where both controllers are made to
walk; policy_node's ``min_speed``/``max_speed``) is clamped into it and said in one line;
a NaN or infinite one is refused. walk.py and run_stack.py clamp their schedules
(:func:`clamp_schedule`), policy_node its ``/cmd_speed``, ``/cmd_vel`` and
``speed_schedule`` commands (:func:`clamp_speed`)."""

from __future__ import annotations

import math
from typing import Sequence

COMMAND_RANGE = (0.7, 1.5)
"""m/s: the commands the controllers are made for (the gait library's speeds)."""


def clamp_speed(value: float, low: float, high: float) -> float:
    """``value`` (m/s) limited to [low, high]; ``ValueError`` if it is NaN or infinite."""
    if not math.isfinite(value):
        raise ValueError(f"speed command must be finite, got {value}")
    return min(max(value, low), high)


def clamp_message(value: float, low: float, high: float, clamped: float, source: str) -> str:
    """The one line for a clamped command from ``source``; any value prints short (``1e+308``,
    not 309 digits)."""
    return f"{source} {value:.4g} m/s is outside [{low:g}, {high:g}]; clamped to {clamped:.2f} m/s"


def clamp_schedule(schedule: Sequence[tuple[float, float]], low: float = COMMAND_RANGE[0],
                   high: float = COMMAND_RANGE[1]) -> tuple[tuple[tuple[float, float], ...], list[str]]:
    """A speed schedule ((s, m/s), ...) with every speed clamped, and one line per clamped
    entry (for the command line to print)."""
    clamped, lines = [], []
    for t, speed in schedule:
        value = clamp_speed(speed, low, high)
        if value != speed:
            lines.append(clamp_message(speed, low, high, value, f"the command at t = {t:g} s,"))
        clamped.append((t, value))
    return tuple(clamped), lines
