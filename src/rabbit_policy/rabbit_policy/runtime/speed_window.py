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

from dataclasses import dataclass
from math import isfinite

import numpy as np

from rabbit_policy.runtime.exact_sum import exact_sum


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
    and sums them correctly rounded (:func:`.exact_sum.exact_sum`, ``math.fsum``'s value: the
    same mean whatever the order or the history before the window) — O(log n) plus a
    compiled sum, per observation. The samples live in numpy arrays (the closed loop hands
    its compiled ticks' speeds over as they are), the oldest beyond ``2 * size`` dropped in
    batches."""

    def __init__(self, size: int = 1000) -> None:
        if size < 1:
            raise ValueError(f"window size must be >= 1, got {size}")
        self.size = size
        self._keep = 2 * size
        # parallel arrays, oldest first, the first _n in use
        self._stamps = np.zeros(2 * self._keep, dtype=np.int64)
        self._speeds = np.zeros(2 * self._keep)
        self._errors = np.zeros(2 * self._keep)
        self._n = 0

    def __len__(self) -> int:
        return min(self._n, self._keep)

    @property
    def newest_stamp(self) -> int | None:
        return int(self._stamps[self._n - 1]) if self._n else None

    def clear(self) -> None:
        self._n = 0

    def _room(self, m: int) -> int:
        """Make room for ``m`` more samples (keeping the newest ``2 * size`` of those there and
        to come); returns where they go."""
        n, keep, capacity = self._n, self._keep, self._stamps.shape[0]
        if n + m > capacity:
            stay = max(0, min(n, keep - m))  # the newest that stay beside the new ones
            for a in (self._stamps, self._speeds, self._errors):
                a[:stay] = a[n - stay:n]
            n = self._n = stay
            if n + m > capacity:  # more new ones than the arrays hold: grow
                grown = n + m + keep
                self._stamps, self._speeds, self._errors = (np.resize(a, grown) for a in
                                                            (self._stamps, self._speeds, self._errors))
        return n

    def add(self, stamp_ns: int, speed: float, desired_speed: float) -> None:
        """Append one sample; non-finite speeds raise ``ValueError``. A stamp older than
        the newest (a simulation reset) starts the window afresh."""
        if not isfinite(speed):
            raise ValueError(f"hip speed must be finite, got {speed}")
        if self._n and stamp_ns < self._stamps[self._n - 1]:
            self.clear()
        i = self._room(1)
        self._stamps[i], self._speeds[i], self._errors[i] = stamp_ns, speed, desired_speed - speed
        self._n = i + 1

    def extend(self, stamps: range, speeds: np.ndarray, desired_speed: float) -> None:
        """Append samples whose stamps rise after the newest, all under one command (m/s):
        as :meth:`add` on each (non-finite speeds raise ``ValueError``, adding none)."""
        speeds = np.asarray(speeds, dtype=float)
        if not np.isfinite(speeds).all():
            raise ValueError("hip speeds must be finite")
        m = len(stamps)
        if m != speeds.shape[0]:
            raise ValueError(f"{m} stamps for {speeds.shape[0]} speeds")
        i = self._room(m)
        self._stamps[i:i + m] = np.arange(stamps.start, stamps.stop, stamps.step)
        self._speeds[i:i + m] = speeds
        np.subtract(desired_speed, speeds, out=self._errors[i:i + m])
        self._n = i + m

    def observation(self, desired_speed: float, stamp_ns: int | None = None,
                    since_ns: int | None = None) -> Observation:
        """Averages over the newest ``size`` samples with ``since_ns`` < stamp <= ``stamp_ns``
        (no bound if None) among the newest ``2 * size``. An empty window gives (v_d, v_d, 0):
        on the commanded speed."""
        total = self._n
        stamps = self._stamps[:total]
        end = total if stamp_ns is None else int(np.searchsorted(stamps, stamp_ns, side="right"))
        start = max(end - self.size, total - self._keep, 0)
        if since_ns is not None and start < end:
            start = max(start, int(np.searchsorted(stamps[start:end], since_ns, side="right")) + start)
        n = end - start
        if n <= 0:
            return Observation(desired_speed, desired_speed, 0.0)
        return Observation(desired_speed, exact_sum(self._speeds[start:end]) / n,
                           exact_sum(self._errors[start:end]) / n)
