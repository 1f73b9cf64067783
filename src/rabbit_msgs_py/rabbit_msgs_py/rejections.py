"""Logging bad input without flooding: every rejection of a kind is counted, and at most one
line per kind is logged per ``period`` s (wall), saying how many were not logged since. A
burst of 10,000 bad messages costs a node a few log lines, not 10,000 (each line is a
rcutils call, and a flood of them once stalled a lockstep run for 0.2 s). ROS-free: it
returns the line to log, and the node logs it (rclpy's logger refuses one call site that
logs at two severities, so each caller keeps its own)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable


@dataclass
class RejectionLog:
    """``line(kind, text)``: count a rejection of ``kind``; the line to log (``text``, and how
    many went unlogged since the last one) if none of that kind was logged in the last
    ``period`` s, else None. ``counts``: every rejection by kind."""

    period: float = 1.0
    clock: Callable[[], float] = time.monotonic
    counts: dict[str, int] = field(default_factory=dict)
    _last: dict[str, float] = field(default_factory=dict)
    _unwritten: dict[str, int] = field(default_factory=dict)

    def line(self, kind: str, text: str | Callable[[], str]) -> str | None:
        """Count it; the line to log, or None within ``period`` of the last one of ``kind``
        (``text`` may be a function, called only for a line that is logged: a flood's refusal
        then builds no text)."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        now = self.clock()
        last = self._last.get(kind)
        if last is not None and now - last < self.period:
            self._unwritten[kind] = self._unwritten.get(kind, 0) + 1
            return None
        skipped = self._unwritten.pop(kind, 0)
        self._last[kind] = now
        text = text() if callable(text) else text
        return text + (f" (and {skipped} more of kind '{kind}' in the last {now - last:.1f} s, not logged: "
                       "counted by kind, their texts may differ)" if skipped and last is not None else "")

    def flush(self) -> list[str]:
        """Lines for the kinds with rejections not logged and none logged for ``period`` s
        (a node calls it from a timer, so a burst's tail is said too)."""
        now, lines = self.clock(), []
        for kind, skipped in list(self._unwritten.items()):
            if now - self._last[kind] >= self.period:
                lines.append(f"{skipped} more of kind '{kind}' after the last one logged, in the last "
                             f"{now - self._last[kind]:.1f} s")
                del self._unwritten[kind]
                self._last[kind] = now
        return lines


def refuse(logger, log: RejectionLog, kind: str, text: str | Callable[[], str]) -> None:
    """Count a refusal of ``kind`` in ``log`` and, when one is due, write its line with
    ``logger.error`` (a node's logger): one line a second per kind however many come."""
    line = log.line(kind, text)
    if line is not None:
        logger.error(line)
