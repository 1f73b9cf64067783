"""The paper's policy inputs: desired speed, mean hip speed and mean speed error over a
window of about one step (200 ticks at 1 kHz). ROS-free and deterministic: samples carry
their sim-time stamp, and an observation is taken at a given stamp from the samples up to
and including it, however late they were delivered."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from math import isfinite


@dataclass(frozen=True)
class Observation:
    """Policy input (m/s): commanded speed v_d, mean hip speed and mean of (v_d - v)."""

    desired_speed: float
    mean_speed: float
    mean_error: float

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.desired_speed, self.mean_speed, self.mean_error)


class SpeedWindow:
    """The last ``size`` hip-speed samples (stamp in ns, speed and error in m/s).

    Keeps ``2 * size`` samples so an observation can still be taken at a stamp a little
    older than the newest sample (the step event may arrive after later samples)."""

    def __init__(self, size: int = 200) -> None:
        if size < 1:
            raise ValueError(f"window size must be >= 1, got {size}")
        self.size = size
        self._samples: deque[tuple[int, float, float]] = deque(maxlen=2 * size)

    def __len__(self) -> int:
        return len(self._samples)

    @property
    def newest_stamp(self) -> int | None:
        return self._samples[-1][0] if self._samples else None

    def clear(self) -> None:
        self._samples.clear()

    def add(self, stamp_ns: int, speed: float, desired_speed: float) -> None:
        """Append one sample; non-finite speeds raise ``ValueError``. A stamp older than
        the newest (a simulation reset) starts the window afresh."""
        if not isfinite(speed):
            raise ValueError(f"hip speed must be finite, got {speed}")
        if self._samples and stamp_ns < self._samples[-1][0]:
            self._samples.clear()
        self._samples.append((stamp_ns, speed, desired_speed - speed))

    def observation(self, desired_speed: float, stamp_ns: int | None = None) -> Observation:
        """Averages over the newest ``size`` samples with stamp <= ``stamp_ns`` (all
        samples if None). An empty window gives (v_d, v_d, 0): on the commanded speed."""
        samples = list(self._samples)
        if stamp_ns is not None:
            end = len(samples)
            while end and samples[end - 1][0] > stamp_ns:
                end -= 1
            samples = samples[:end]
        samples = samples[-self.size:]
        if not samples:
            return Observation(desired_speed, desired_speed, 0.0)
        n = len(samples)
        return Observation(
            desired_speed,
            sum(s[1] for s in samples) / n,
            sum(s[2] for s in samples) / n,
        )
