"""Choosing among a training run's policies on held-out checks, before judging one on checks 1-6.

The training run's acceptance (:mod:`.acceptance`: 9 constant speeds and one schedule) is
what ``best.pt`` is chosen on; the policies it chose lost random sequences, push margin and
the 1.0 m/s cycle where it does not look (docs/learning.md). :func:`screen` runs checks 2, 3
and 5 of the broad evaluation (:mod:`.robustness`) on points that checks 1-6 do not use, so
that the policy it picks is judged on checks 1-6 without having been chosen on them:

* the ordered speed changes at the phases halfway between check 2's (1/8, 3/8, 5/8, 7/8);
* random command sequences from other seeds (check 3 uses ``seed`` 0);
* the judged model errors (check 5's) at 0.85, 1.15 and 1.4 m/s (check 5: 0.7, 1.0, 1.3).

:func:`screen_rank` orders the results: fewest failures in all (a change not reached within
4 s, a sequence that fell or stalled, a model case off by more than 0.05 m/s), then fewest
falls and stalls.
"""

from __future__ import annotations

from dataclasses import replace

from rabbit_policy.evaluation.acceptance import BroadCriteria
from rabbit_policy.evaluation.robustness import (
    MODEL_ERRORS,
    MapFn,
    RobustnessConfig,
    model_errors,
    random_sequences,
    transitions,
)
from rabbit_policy.runtime.policies import Policy

HELD_OUT = RobustnessConfig(
    change_phases=(0.125, 0.375, 0.625, 0.875),
    random_episodes=30,
    seed=7,
    model_speeds=(0.85, 1.15, 1.4),
    model_errors=tuple(m for m in MODEL_ERRORS if m.name in BroadCriteria().judged_models),
)
"""The screen's points: none of them is one of checks 1-6's (``RobustnessConfig()``)."""


def screen(policy: Policy, config: RobustnessConfig = HELD_OUT, map_fn: MapFn = map) -> dict:
    """Checks 2, 3 and 5 of :mod:`.robustness` on ``config``'s points; JSON-ready counts
    (``*_failed`` lists name what failed) and ``failures``, ``falls`` for :func:`screen_rank`."""
    changes = transitions(policy, config, map_fn)
    sequences = random_sequences(policy, config, map_fn)
    models = model_errors(policy, config, map_fn)
    change_falls = sum(r["outcome"] != "walked" for r in changes["rows"])
    sequence_falls = sum(r["outcome"] != "walked" for r in sequences["rows"])
    model_falls = sum(r["outcome"] != "walked" for r in models["rows"])
    return {
        "changes": f"{sum(r['passed'] for r in changes['rows'])}/{len(changes['rows'])}",
        "changes_failed": [[r["from"], r["to"], r["phase"], r["outcome"]] for r in changes["rows"] if not r["passed"]],
        "random": f"{sequences['passed']}/{sequences['total']}",
        "random_failed": [[r["seed"], r["outcome"]] for r in sequences["rows"] if r["outcome"] != "walked"],
        "models": f"{models['passed']}/{models['total']}",
        "models_failed": [[r["case"], r["speed"], r["outcome"], None if r["error"] is None else round(r["error"], 4)]
                          for r in models["rows"] if not r["passed"]],
        "failures": (len(changes["rows"]) - sum(r["passed"] for r in changes["rows"])
                     + sequences["total"] - sequences["passed"] + models["total"] - models["passed"]),
        "falls": change_falls + sequence_falls + model_falls,
    }


def screen_rank(result: dict) -> tuple[int, int]:
    """Sort key of a :func:`screen` result: fewer failures, then fewer falls and stalls."""
    return result["failures"], result["falls"]


def quick_screen_config() -> RobustnessConfig:
    """A few seconds' version of :data:`HELD_OUT` (the test suite's)."""
    return replace(HELD_OUT, transition_speeds=(0.8, 1.4), change_phases=(0.375,), transition_settle=3.0,
                   random_episodes=1, random_duration=8.0, model_speeds=(1.15,), model_duration=6.0,
                   model_errors=HELD_OUT.model_errors[:1])
