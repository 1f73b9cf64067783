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

from collections import deque
from dataclasses import dataclass
from math import isfinite


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
    older than the newest sample (the step event may arrive after later samples)."""

    def __init__(self, size: int = 1000) -> None:
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

    def observation(self, desired_speed: float, stamp_ns: int | None = None,
                    since_ns: int | None = None) -> Observation:
        """Averages over the newest ``size`` samples with ``since_ns`` < stamp <= ``stamp_ns``
        (no bound if None). An empty window gives (v_d, v_d, 0): on the commanded speed."""
        # newest first: skip samples after stamp_ns, stop at since_ns or after size samples
        picked: list[tuple[int, float, float]] = []
        for sample in reversed(self._samples):
            stamp = sample[0]
            if stamp_ns is not None and stamp > stamp_ns:
                continue
            if (since_ns is not None and stamp <= since_ns) or len(picked) == self.size:
                break
            picked.append(sample)
        if not picked:
            return Observation(desired_speed, desired_speed, 0.0)
        speed_sum = error_sum = 0.0
        for _stamp, speed, error in reversed(picked):  # summed oldest first, as they came
            speed_sum += speed
            error_sum += error
        n = len(picked)
        return Observation(desired_speed, speed_sum / n, error_sum / n)
