"""The paper's policy inputs: desired speed, mean hip speed and mean speed error over about
one walking step. ROS-free and deterministic: samples carry their sim-time stamp, and an
observation is taken at a given stamp from the samples up to and including it, however
late they were delivered.

The paper averages over "about one walking step, which takes about 200 simulation steps"
(its simulator's steps). Here a step lasts 390-730 ticks of 1 ms, so the window is *the
last step itself*: the samples after the previous touchdown up to this one (``since_ns``),
at most ``size`` of them. The mean over a whole step is the step's average speed, the
quantity the speed command is about; a fixed 200-tick window would read only the end of
the step, which is 0.1-0.2 m/s faster than the step average on the slow gaits."""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass
from math import fsum, isfinite


@dataclass(frozen=True)
class Observation:
    """Policy input (m/s): commanded speed v_d, mean hip speed and mean of (v_d - v); ``body``:
    the body state at the decision (:mod:`.body`; the closed loop adds it, for a policy that
    reads it), else None."""

    desired_speed: float
    mean_speed: float
    mean_error: float
    body: tuple[float, ...] | None = None

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.desired_speed, self.mean_speed, self.mean_error)


class SpeedWindow:
    """The last ``size`` hip-speed samples (stamp in ns, speed and error in m/s).

    Keeps ``2 * size`` samples so an observation can still be taken at a stamp a little
    older than the newest sample (the step event may arrive after later samples). Stamps
    only grow (an older one starts afresh), so an observation finds its samples by bisection
    and sums them with ``math.fsum`` (correctly rounded: the same mean whatever the order or
    the history before the window) — O(log n) plus a sum in C, per observation."""

    def __init__(self, size: int = 1000) -> None:
        if size < 1:
            raise ValueError(f"window size must be >= 1, got {size}")
        self.size = size
        self._keep = 2 * size
        # parallel lists, oldest first; the oldest beyond 2 * size are dropped in batches
        self._stamps: list[int] = []
        self._speeds: list[float] = []
        self._errors: list[float] = []

    def __len__(self) -> int:
        return min(len(self._stamps), self._keep)

    @property
    def newest_stamp(self) -> int | None:
        return self._stamps[-1] if self._stamps else None

    def clear(self) -> None:
        self._stamps.clear()
        self._speeds.clear()
        self._errors.clear()

    def add(self, stamp_ns: int, speed: float, desired_speed: float) -> None:
        """Append one sample; non-finite speeds raise ``ValueError``. A stamp older than
        the newest (a simulation reset) starts the window afresh."""
        if not isfinite(speed):
            raise ValueError(f"hip speed must be finite, got {speed}")
        stamps = self._stamps
        if stamps and stamp_ns < stamps[-1]:
            self.clear()
        elif len(stamps) >= 2 * self._keep:  # amortised: drop the oldest half at once
            drop = len(stamps) - self._keep
            del stamps[:drop], self._speeds[:drop], self._errors[:drop]
        stamps.append(stamp_ns)
        self._speeds.append(speed)
        self._errors.append(desired_speed - speed)

    def extend(self, stamps: range, speeds: list[float], desired_speed: float) -> None:
        """Append samples whose stamps rise after the newest, all under one command (m/s):
        as :meth:`add` on each (non-finite speeds raise ``ValueError``, adding none)."""
        if not all(isfinite(v) for v in speeds):
            raise ValueError("hip speeds must be finite")
        self._stamps.extend(stamps)
        self._speeds.extend(speeds)
        self._errors.extend([desired_speed - v for v in speeds])
        if len(self._stamps) >= 2 * self._keep:  # drop the oldest beyond the newest 2 * size
            drop = len(self._stamps) - self._keep
            del self._stamps[:drop], self._speeds[:drop], self._errors[:drop]

    def observation(self, desired_speed: float, stamp_ns: int | None = None,
                    since_ns: int | None = None) -> Observation:
        """Averages over the newest ``size`` samples with ``since_ns`` < stamp <= ``stamp_ns``
        (no bound if None) among the newest ``2 * size``. An empty window gives (v_d, v_d, 0):
        on the commanded speed."""
        stamps = self._stamps
        end = len(stamps) if stamp_ns is None else bisect_right(stamps, stamp_ns)
        start = max(end - self.size, len(stamps) - self._keep, 0)
        if since_ns is not None:
            start = max(start, bisect_right(stamps, since_ns, start, end) if start < end else start)
        n = end - start
        if n <= 0:
            return Observation(desired_speed, desired_speed, 0.0)
        return Observation(desired_speed, fsum(self._speeds[start:end]) / n, fsum(self._errors[start:end]) / n)
