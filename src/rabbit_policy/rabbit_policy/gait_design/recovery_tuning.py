"""Tuning the recovery controller's constants (:mod:`rabbit_policy.runtime.recovery`) on a push
grid, as a model-based controller's gains are tuned: CMA-ES over the four offsets, the
saturation ``full`` and the ``threshold``, maximising the pushes survived over a grid of speeds, phases and impulses
(multiples of classic HZD's backward margin). The grid is the training set; the margins
(:func:`rabbit_policy.evaluation.robustness.push_margins`) and the rest of the evaluation judge
the result on every phase and impulse."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

from rabbit_policy.evaluation.robustness import phase_times, push_survived
from rabbit_policy.runtime.recovery import RecoveryConfig, RecoveryPolicy

MapFn = Callable[[Callable, Iterable], Iterable]


@dataclass(frozen=True)
class TuningConfig:
    """The grid (speeds m/s with classic's backward margin in N s there, phases of the step,
    impulse factors) and the search (generations, population, initial step in rad)."""

    margins: tuple[tuple[float, float], ...] = ((0.7, 5.0), (1.0, 9.0), (1.3, 14.0))
    phases: tuple[float, ...] = tuple(i / 8 for i in range(8))
    factors: tuple[float, ...] = (1.5, 2.0)
    generations: int = 6
    popsize: int = 8
    sigma: float = 0.05
    push_horizon: float = 5.0
    settle: float = 3.0
    push_duration: float = 0.1
    seed: int = 3


def push_cases(policy, config: TuningConfig) -> list[tuple[float, float, float]]:
    """(speed, push time s, impulse N s signed) for every grid point; the push times from the
    undisturbed walk (the recovery controller walks as classic does when nothing pushes)."""
    cases = []
    for speed, margin in config.margins:
        times = phase_times(policy, speed, config.settle, config.phases)
        if times is None:
            raise RuntimeError(f"the controller does not walk at {speed} m/s")
        cases += [(speed, t, -float(np.ceil(f * margin - 1e-9))) for f in config.factors for t in times]
    return cases


def survivals(policy: RecoveryPolicy, cases, config: TuningConfig, map_fn: MapFn = map) -> int:
    """How many of ``cases`` the controller survives (the push margin's rule)."""
    return sum(map_fn(push_survived, [(policy, s, t, i, config) for s, t, i in cases]))


def _decode(x: np.ndarray) -> RecoveryConfig:
    return RecoveryConfig(tuple(float(v) for v in x[:4]), float(max(x[5], 0.0)), float(max(x[4], 0.02)))


def tune(policy: RecoveryPolicy, config: TuningConfig, map_fn: MapFn = map,
         log: Callable[[str], None] = lambda _: None) -> dict:
    """CMA-ES from ``policy.config``; returns the best constants found, their score and each
    generation's scores."""
    import cma

    cases = push_cases(policy, config)
    start = policy.config
    x0 = np.array(list(start.offsets) + [start.full, start.threshold])
    best_score = survivals(policy, cases, config, map_fn)
    best, history = start, [{"generation": 0, "scores": [best_score]}]
    log(f"start {start}: {best_score}/{len(cases)}")
    es = cma.CMAEvolutionStrategy(x0, config.sigma, {"popsize": config.popsize, "seed": config.seed, "verbose": -9})
    for generation in range(1, config.generations + 1):
        xs = es.ask()
        scores = [survivals(policy.with_config(_decode(np.asarray(x))), cases, config, map_fn) for x in xs]
        es.tell(xs, [-s for s in scores])
        i = int(np.argmax(scores))
        if scores[i] > best_score:
            best_score, best = scores[i], _decode(np.asarray(xs[i]))
        history.append({"generation": generation, "scores": scores})
        log(f"generation {generation}: best {max(scores)}, so far {best_score}/{len(cases)} {best}")
    return {"best": {"offsets": list(best.offsets), "threshold": best.threshold, "full": best.full},
            "survived": best_score, "cases": len(cases), "history": history}
