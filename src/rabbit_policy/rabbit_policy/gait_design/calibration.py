"""Calibrate a gait library's interpolation: walk blends of each two neighbouring gaits at
fixed weights and record the mean speed each walks at (or that it fell or stalled), so
:meth:`~rabbit_policy.runtime.gait_library.GaitLibrary.interpolate` can pick the blend that
walks at the commanded speed (see :mod:`rabbit_policy.runtime.gait_library`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

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


def _hip_profile_row(job: tuple) -> tuple[float, ...]:
    from rabbit_policy.experiment.loop import ClosedLoop
    from rabbit_policy.runtime.policies import make_policy

    gait_dir, speed, bins, settle, duration = job
    loop = ClosedLoop(Scenario.constant(speed), make_policy("classic", gait_dir=gait_dir))
    sums, counts = [0.0] * bins, [0] * bins
    settle_ticks = int(round(settle / loop.model.opt.timestep))

    def observe(l, _torques) -> None:
        if l.ticks > settle_ticks:
            b = min(int(l.controller.tau * bins), bins - 1)
            sums[b] += float(l.data.qvel[0])
            counts[b] += 1

    loop.observer = observe
    if loop.run(settle + duration):
        raise RuntimeError(f"classic HZD does not walk at {speed} m/s: no hip speed profile")
    filled = [s / c if c else None for s, c in zip(sums, counts)]
    known = [(b, v) for b, v in enumerate(filled) if v is not None]
    if len(known) < 2:
        raise RuntimeError(f"the walk at {speed} m/s visited fewer than 2 phase bins")
    xs, vs = zip(*known)
    return tuple(float(v) for v in np.interp(range(bins), xs, vs))  # a bin the phase skipped: its neighbours'


def calibrate_hip_profile(library: GaitLibrary, gait_dir: str | None = None, bins: int = 20, settle: float = 2.0,
                          duration: float = 6.0, map_fn: MapFn = map):
    """The undisturbed hip velocity by phase at each of the library's speeds, walked by classic
    HZD (:class:`~rabbit_policy.runtime.recovery.HipSpeedProfile`): the mean over ``duration``
    s after ``settle`` s, in ``bins`` equal phase bins."""
    from rabbit_policy.runtime.recovery import HipSpeedProfile

    rows = list(map_fn(_hip_profile_row, [(gait_dir, s, bins, settle, duration) for s in library.speeds]))
    return HipSpeedProfile(tuple(library.speeds), tuple(rows))
