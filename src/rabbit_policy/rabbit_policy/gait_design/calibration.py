"""Calibrate a gait library's interpolation: walk blends of each two neighbouring gaits at
fixed weights and record the mean speed each walks at (or that it fell or stalled), so
:meth:`~rabbit_policy.runtime.gait_library.GaitLibrary.interpolate` can pick the blend that
walks at the commanded speed (see :mod:`rabbit_policy.runtime.gait_library`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.gait_library import Calibration, GaitLibrary
from rabbit_policy.runtime.policies import GaitCommand

MapFn = Callable[[Callable, Iterable], Iterable]


@dataclass(frozen=True)
class CalibrationConfig:
    """``weights`` blend weights per pair (evenly from 0 to 1), each walked ``duration`` s
    (sim time); the mean speed is over the second half."""

    weights: int = 11
    duration: float = 20.0

    def __post_init__(self) -> None:
        if self.weights < 2 or not self.duration > 0.0:
            raise ValueError("a calibration needs >= 2 weights per pair and a duration > 0 s")


def _blend_speed(job: tuple) -> float | None:
    library, pair, w, duration = job
    gait = library.blend(pair, w)
    result = walk(None, Scenario.constant(gait.speed), duration, start=GaitCommand(gait.alpha, gait.kd), kp=gait.kp)
    return None if result.failed else float(result.mean_speed(0.5 * duration))


def calibrate(library: GaitLibrary, config: CalibrationConfig = CalibrationConfig(), map_fn: MapFn = map) -> Calibration:
    """Measure every blend (pairs x weights walks, run through ``map_fn``)."""
    weights = [k / (config.weights - 1) for k in range(config.weights)]
    bare = GaitLibrary(library.gaits)  # blends by weight, whatever calibration the library had
    jobs = [(bare, pair, w, config.duration) for pair in range(len(library.gaits) - 1) for w in weights]
    speeds = list(map_fn(_blend_speed, jobs))
    pairs = tuple(tuple(zip(weights, speeds[k * len(weights):(k + 1) * len(weights)]))
                  for k in range(len(library.gaits) - 1))
    return Calibration(pairs, {"weights": config.weights, "duration_s": config.duration,
                               "gait_speeds": library.speeds, "mean_speed": "hip displacement over the second half"})
