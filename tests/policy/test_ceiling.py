"""The push-recovery ceiling oracle (rabbit_policy.evaluation.ceiling): a cloned loop goes on as
the original, a zero action is classic HZD, and the search finds a survivor where classic falls."""

from __future__ import annotations

import numpy as np
import pytest

from rabbit_policy.evaluation.ceiling import (FAMILIES, CeilingConfig, clone_loop, ladder, prepare, rollout,
                                              search, summarize)
from rabbit_policy.evaluation.robustness import phase_times
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.spec.make import make_policy

pytestmark = pytest.mark.sim

CONFIG = CeilingConfig(budget=48, popsize=8, horizon=3.0)


@pytest.fixture(scope="module")
def push_time() -> float:
    return phase_times(make_policy("classic"), 1.0, CONFIG.settle, [0.875])[0]


@pytest.mark.slow
def test_a_cloned_loop_goes_on_exactly_as_the_original(push_time):
    case = prepare(1.0, -9.0, CONFIG, push_time)
    first, second = clone_loop(case.loop), clone_loop(case.loop)
    first.run(max_ticks=1500)
    assert case.loop.ticks == case.push_tick  # the case itself is not moved by its clones
    second.run(max_ticks=1500)
    np.testing.assert_array_equal(first.data.qpos, second.data.qpos)
    assert first.touchdowns == second.touchdowns


@pytest.mark.slow
@pytest.mark.parametrize("impulse", [9.0, 10.0])
def test_a_rollout_without_actions_is_classic_hzd(push_time, impulse):
    case = prepare(1.0, -impulse, CONFIG, push_time)
    push = Push(push_time, -impulse / CONFIG.push_duration, CONFIG.push_duration)
    reference = walk(make_policy("classic"), Scenario.constant(1.0, pushes=(push,)), push_time + CONFIG.horizon)
    assert rollout(case, FAMILIES["a_blended"], None, CONFIG)["survived"] == (not reference.failed)
    zeros = np.zeros((CONFIG.blocks, FAMILIES["b_at_once"].dims))
    assert rollout(case, FAMILIES["b_at_once"], zeros, CONFIG)["survived"] == (not reference.failed)


@pytest.mark.slow
def test_the_oracle_finds_a_recovery_where_classic_stalls(push_time):
    case = prepare(1.0, -14.0, CONFIG, push_time)
    assert not rollout(case, FAMILIES["b_at_once"], None, CONFIG)["survived"]
    found = search(case, FAMILIES["b_at_once"], CONFIG, seed=1)
    assert found["found"]
    again = rollout(case, FAMILIES["b_at_once"], np.array(found["params"]), CONFIG)
    assert again["survived"]  # the survivor's actions replay to a survival


def test_ladder_and_summary():
    assert ladder(9, (1.5, 2.0, 2.5, 3.0)) == [14.0, 18.0, 23.0, 27.0]
    rows = [{"family": "x", "speed": 1.0, "phase": p, "reached_Ns": r} for p, r in ((0.0, 18), (0.5, 14), (0.875, 14))]
    assert summarize(rows) == [{"family": "x", "speed": 1.0, "ceiling_Ns": 14, "binding_phases": [0.5, 0.875],
                                "phases": 3}]
    with pytest.raises(ValueError):
        CeilingConfig(budget=0)
