"""The classic HZD gait library shipped as package data (``rabbit_policy/gaits/*.json``).

Each file is a :class:`rabbit_hzd_controller.gait.Gait` designed by
:mod:`rabbit_policy.gait_design.optimization` for one average speed; ``scripts/optimize_gaits.py``
regenerates them. A policy picks the gait nearest to the commanded speed, or blends
the two neighbouring gaits linearly (alpha and Kd both: the coefficients are joint
waypoints, so a blend of two nearby gaits is a gait in between).
"""

from __future__ import annotations

from bisect import bisect_left
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Iterable

import numpy as np

from rabbit_hzd_controller.gait import Gait


def packaged_gait_dir() -> Path:
    """Directory of the shipped gait files."""
    return Path(str(files("rabbit_policy") / "gaits"))


@dataclass(frozen=True)
class GaitLibrary:
    """Gaits sorted by design speed (m/s)."""

    gaits: tuple[Gait, ...]

    def __post_init__(self) -> None:
        if not self.gaits:
            raise ValueError("a gait library needs at least one gait")
        ordered = tuple(sorted(self.gaits, key=lambda g: g.speed))
        object.__setattr__(self, "gaits", ordered)

    @classmethod
    def load(cls, directory: str | Path | None = None) -> "GaitLibrary":
        """Load every ``*.json`` gait in ``directory`` (default: the packaged library)."""
        directory = Path(directory) if directory else packaged_gait_dir()
        paths = sorted(directory.glob("*.json"))
        if not paths:
            raise FileNotFoundError(f"no gait files (*.json) in {directory}")
        return cls(tuple(Gait.load(p) for p in paths))

    @classmethod
    def from_gaits(cls, gaits: Iterable[Gait]) -> "GaitLibrary":
        return cls(tuple(gaits))

    @property
    def speeds(self) -> list[float]:
        return [g.speed for g in self.gaits]

    def nearest(self, speed: float) -> Gait:
        """The gait whose design speed is closest to ``speed`` (ties: the slower one)."""
        return min(self.gaits, key=lambda g: (abs(g.speed - speed), g.speed))

    def interpolate(self, speed: float) -> Gait:
        """Linear blend of the two gaits around ``speed``; clamps outside the range."""
        speeds = self.speeds
        if speed <= speeds[0]:
            return self.gaits[0]
        if speed >= speeds[-1]:
            return self.gaits[-1]
        i = bisect_left(speeds, speed)
        lo, hi = self.gaits[i - 1], self.gaits[i]
        w = (speed - lo.speed) / (hi.speed - lo.speed)
        alpha = (1.0 - w) * np.asarray(lo.alpha) + w * np.asarray(hi.alpha)
        return Gait(
            alpha=tuple(alpha),
            kd=(1.0 - w) * lo.kd + w * hi.kd,
            kp=(1.0 - w) * lo.kp + w * hi.kp,
            speed=speed,
            step_length=(1.0 - w) * lo.step_length + w * hi.step_length,
            step_period=(1.0 - w) * lo.step_period + w * hi.step_period,
            info={"interpolated_from": [lo.speed, hi.speed], "weight": w},
        )
