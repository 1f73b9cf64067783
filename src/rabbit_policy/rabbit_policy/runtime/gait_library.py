"""The classic HZD gait library shipped as package data (``rabbit_policy/gaits/*.json``).

Each file ``gait_*.json`` is a :class:`rabbit_hzd_controller.gait.Gait` designed by
:mod:`rabbit_policy.gait_design.optimization` for one average speed; ``scripts/optimize_gaits.py``
regenerates them. A policy picks the gait nearest to the commanded speed, or blends
the two neighbouring gaits linearly (alpha and Kd both: the coefficients are joint
waypoints).

A blend of two gaits designed apart is not the gait for the speed in between: it may
stall or walk faster than either (docs/gait_library.md measures it). The library
therefore carries a *calibration*
(``interpolation.json``, :class:`Calibration`, made by ``scripts/calibrate_library.py``):
the mean speed each blend weight actually walks at. :meth:`GaitLibrary.interpolate`
picks, between the two gaits around the command, the blend whose *measured* speed is
the command, among the weights that walked; without a calibration it blends by design
speed.
"""

from __future__ import annotations

import json
from bisect import bisect_left
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path
from typing import Iterable

import numpy as np

from rabbit_hzd_controller.gait import Gait


CALIBRATION_FILE = "interpolation.json"


@dataclass(frozen=True)
class Calibration:
    """Measured speed (m/s) of blends of neighbouring gaits: ``pairs[i]`` holds, for the
    gaits i and i+1 (by design speed), ``(weight, mean speed or None if it fell or
    stalled)`` rows in increasing weight, weight 0 = gait i, 1 = gait i+1."""

    pairs: tuple[tuple[tuple[float, float | None], ...], ...]
    info: dict = field(default_factory=dict)

    def weight_for(self, pair: int, speed: float) -> float | None:
        """The blend weight that walks at ``speed`` m/s between gaits ``pair`` and ``pair``+1
        (linear between two measured weights that both walked and bracket it; the
        bracket nearest the design-speed weight if several do), or None if none does."""
        rows = self.pairs[pair]
        candidates = []
        for (w0, v0), (w1, v1) in zip(rows, rows[1:]):  # never across a weight that failed
            if v0 is not None and v1 is not None and min(v0, v1) <= speed <= max(v0, v1) and v0 != v1:
                candidates.append(w0 + (w1 - w0) * (speed - v0) / (v1 - v0))
        if not candidates:
            return None
        return min(candidates, key=lambda w: abs(w - 0.5))

    def to_dict(self) -> dict:
        return {"pairs": [[list(row) for row in rows] for rows in self.pairs], "info": self.info}

    @classmethod
    def from_dict(cls, data: dict) -> "Calibration":
        return cls(tuple(tuple((float(w), None if v is None else float(v)) for w, v in rows)
                         for rows in data["pairs"]), data.get("info", {}))


def packaged_gait_dir() -> Path:
    """Directory of the shipped gait files."""
    return Path(str(files("rabbit_policy") / "gaits"))


@dataclass(frozen=True)
class GaitLibrary:
    """Gaits sorted by design speed (m/s)."""

    gaits: tuple[Gait, ...]
    calibration: Calibration | None = None

    def __post_init__(self) -> None:
        if not self.gaits:
            raise ValueError("a gait library needs at least one gait")
        ordered = tuple(sorted(self.gaits, key=lambda g: g.speed))
        object.__setattr__(self, "gaits", ordered)
        if self.calibration is not None and len(self.calibration.pairs) != len(ordered) - 1:
            raise ValueError(f"the calibration covers {len(self.calibration.pairs)} gait pairs, the library has "
                             f"{len(ordered) - 1}")

    @classmethod
    def load(cls, directory: str | Path | None = None) -> "GaitLibrary":
        """Load every ``*.json`` gait in ``directory`` (default: the packaged library) and
        its ``interpolation.json`` calibration, if there is one."""
        directory = Path(directory) if directory else packaged_gait_dir()
        paths = sorted(p for p in directory.glob("*.json") if p.name != CALIBRATION_FILE)
        if not paths:
            raise FileNotFoundError(f"no gait files (*.json) in {directory}")
        gaits = tuple(Gait.load(p) for p in paths)
        calibration_path = directory / CALIBRATION_FILE
        calibration = None
        if calibration_path.is_file():
            try:
                calibration = Calibration.from_dict(json.loads(calibration_path.read_text()))
            except (TypeError, ValueError, KeyError, AttributeError) as exc:
                raise ValueError(f"{calibration_path} is not a calibration file ({str(exc)[:160]})") from None
        return cls(gaits, calibration)

    @classmethod
    def from_gaits(cls, gaits: Iterable[Gait]) -> "GaitLibrary":
        return cls(tuple(gaits))

    @property
    def speeds(self) -> list[float]:
        return [g.speed for g in self.gaits]

    @property
    def speed_range(self) -> tuple[float, float]:
        """The slowest and the fastest gait's design speed (m/s): what :meth:`interpolate`
        can be asked for without clamping."""
        return self.gaits[0].speed, self.gaits[-1].speed

    def nearest(self, speed: float) -> Gait:
        """The gait whose design speed is closest to ``speed`` (ties: the slower one)."""
        return min(self.gaits, key=lambda g: (abs(g.speed - speed), g.speed))

    def interpolate(self, speed: float) -> Gait:
        """Linear blend of the two gaits around ``speed``; clamps outside the range. With
        a calibration, the blend of two neighbouring gaits measured to walk at ``speed``
        (of several, the one whose design speed is nearest; see the module docstring);
        where none does, the nearest gait."""
        speeds = self.speeds
        if speed <= speeds[0]:
            return self.gaits[0]
        if speed >= speeds[-1]:
            return self.gaits[-1]
        if self.calibration is None:
            i = bisect_left(speeds, speed)
            lo, hi = self.gaits[i - 1], self.gaits[i]
            return self.blend(i - 1, (speed - lo.speed) / (hi.speed - lo.speed), speed)
        found = []  # (distance of the blend's design speed from the command, pair, weight)
        for pair in range(len(self.gaits) - 1):
            w = self.calibration.weight_for(pair, speed)
            if w is not None:
                design = (1.0 - w) * speeds[pair] + w * speeds[pair + 1]
                found.append((abs(design - speed), pair, w))
        if not found:
            return self.nearest(speed)
        _, pair, w = min(found)
        return self.blend(pair, w, speed)

    def blend(self, pair: int, w: float, speed: float | None = None) -> Gait:
        """The blend ``(1 - w)`` gait ``pair`` + ``w`` gait ``pair + 1`` (``speed``: the
        design speed it is labelled with; default the linear one)."""
        lo, hi = self.gaits[pair], self.gaits[pair + 1]
        speed = (1.0 - w) * lo.speed + w * hi.speed if speed is None else speed
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
