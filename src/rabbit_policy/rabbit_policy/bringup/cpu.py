"""CPU time each process of a run spends per 1 kHz tick (Linux: ``/proc/PID/stat``, user
plus system time of all its threads, the DDS threads too; elsewhere nothing is measured)."""

from __future__ import annotations

import os
from pathlib import Path

from rabbit_msgs_py.decision_ticks import TICK_NS


def process_cpu_seconds(pid: int) -> float | None:
    """User + system CPU s of process ``pid`` so far (None: not readable, or not Linux)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


class CpuMeter:
    """CPU s per tick of named processes between two sim times (ns): :meth:`start` when the
    walk starts, :meth:`per_tick_us` at its end (the processes still alive)."""

    def __init__(self, pids: dict[str, int]) -> None:
        self.pids = pids
        self._start: tuple[int, dict[str, float | None]] | None = None

    @property
    def started(self) -> bool:
        return self._start is not None

    def start(self, stamp: int) -> None:
        self._start = (stamp, {name: process_cpu_seconds(pid) for name, pid in self.pids.items()})

    def per_tick_us(self, stamp: int) -> dict[str, float] | None:
        """µs of CPU per tick of each process since :meth:`start` (and their ``total``); None
        when nothing was measured (no ticks, or no /proc)."""
        if self._start is None or stamp <= self._start[0]:
            return None
        ticks = (stamp - self._start[0]) / TICK_NS
        out = {}
        for name, pid in self.pids.items():
            now, then = process_cpu_seconds(pid), self._start[1][name]
            if now is None or then is None:
                return None
            out[name] = round((now - then) / ticks * 1e6, 1)
        out["total"] = round(sum(out.values()), 1)
        return out
