"""The gait optimizer: its objective is deterministic, ranks falls below walks, and CMA-ES
improves on its starting point; ``optimize_gaits.py --friction-limit`` designs under the limit
it is given."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rabbit_hzd_controller.gait import Gait
from rabbit_policy.runtime.gait_library import GaitLibrary, packaged_gait_dir
from rabbit_policy.gait_design.optimization import (
    KD_SCALE,
    GaitProblem,
    decision_to_gait_params,
    evaluate,
    gait_to_decision,
    optimize_gait,
)
from rabbit_policy.gait_design.seed import SeedPattern, seed_free_alpha

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def gait() -> Gait:
    return GaitLibrary.load().nearest(1.0)


def test_decision_vector_round_trip(gait):
    x = gait_to_decision(gait)
    alpha, kd = decision_to_gait_params(x, GaitProblem(speed=gait.speed))
    np.testing.assert_allclose(alpha, gait.alpha)
    assert kd == pytest.approx(gait.kd)


def test_objective_reproduces_the_stored_cost(gait):
    result = evaluate(gait_to_decision(gait), GaitProblem(speed=gait.speed))
    assert not result.fell
    assert result.cost == pytest.approx(gait.cost, rel=1e-9)
    assert result.max_friction_ratio <= 0.8
    assert result.min_clearance > 0.0


def test_a_fall_costs_more_than_any_walk(gait):
    x = gait_to_decision(gait)
    x[-1] = 0.0  # no damping at all
    x[1] += 0.6  # and a badly bent stance knee at touchdown
    bad = evaluate(x, GaitProblem(speed=gait.speed))
    assert bad.fell
    assert bad.cost > 1000.0 > evaluate(gait_to_decision(gait), GaitProblem(speed=gait.speed)).cost


@pytest.mark.slow
def test_cma_improves_on_the_kinematic_seed():
    problem = GaitProblem(speed=1.0, horizon=4.0)
    x0 = np.concatenate([seed_free_alpha(SeedPattern(step_length=0.4, hip_height=0.76, torso_pitch=0.05)),
                         [60.0 / KD_SCALE]])
    start = evaluate(x0, problem).cost
    result = optimize_gait(problem, x0, max_generations=3, popsize=8, seed=3)
    assert result.evaluations == 24
    assert result.evaluation.cost <= start
    assert result.gait.speed == 1.0


@pytest.mark.slow
def test_approach_term_measures_convergence_as_stored_in_the_shipped_gait():
    """The shipped 1.5 m/s gait was designed with approach_from (its file records from which
    speeds): the term re-measures what its file records, and a candidate that never gets
    there scores worse."""
    from rabbit_policy.gait_design.optimization import approach, approach_cost, total_cost

    fast = GaitLibrary.load().nearest(1.5)
    stored = fast.info["approach"]
    starts = tuple(sorted(float(k[5:]) for k in stored if k.startswith("from_")))
    assert len(starts) == 2
    problem = GaitProblem(speed=1.5, approach_from=starts, approach_weight=stored["cost"] / sum(
        stored[f"from_{s:.2f}"]["shortfall"] for s in starts))
    term, measured = approach_cost(gait_to_decision(fast), problem)
    slowest = starts[0]
    assert term == pytest.approx(stored["cost"], rel=1e-9)
    assert measured[slowest].reach_time == pytest.approx(stored[f"from_{slowest:.2f}"]["reach_time"], abs=1e-9)
    assert 0.0 < measured[slowest].reach_time < 5.0 and not measured[slowest].fell
    # the 1.2 m/s gait commanded as if it were the 1.5 one stays 0.3 m/s short: a larger shortfall
    slow = approach(gait_to_decision(GaitLibrary.load().nearest(1.2)), problem, GaitLibrary.load().nearest(slowest))
    assert slow.reach_time is None and slow.shortfall > 3 * measured[slowest].shortfall  # ~0.25 m/s x 8 s
    base = evaluate(gait_to_decision(fast), problem).cost
    assert total_cost(gait_to_decision(fast), problem) == pytest.approx(base + term)


def test_a_lower_friction_limit_penalises_a_gait_that_needs_more_friction(gait):
    """The 1.0 m/s gait's stance foot needs |F_t|/F_n up to about 0.5 (docs/learning/friction/):
    under the shipped cone limit 0.6 it pays no friction penalty, under 0.3 it does, and the
    cost grows by exactly that penalty."""
    x = gait_to_decision(gait)
    shipped = evaluate(x, GaitProblem(speed=gait.speed))
    strict = evaluate(x, GaitProblem(speed=gait.speed, friction_limit=0.3))
    assert 0.3 < shipped.max_friction_ratio < 0.6
    assert shipped.penalties["friction"] == 0.0 < strict.penalties["friction"]
    assert strict.cost - shipped.cost == pytest.approx(strict.penalties["friction"])


@pytest.mark.slow
def test_optimize_gaits_designs_under_the_friction_limit_it_is_given(tmp_path):
    root = Path(__file__).resolve().parents[2]
    shutil.copy(packaged_gait_dir() / "gait_1.10.json", tmp_path)
    script = [sys.executable, "scripts/optimize_gaits.py", "--speeds", "1.1", "--refine", "--out", str(tmp_path),
              "--iterations", "1", "--validate", "2", "--workers", "1"]
    out = subprocess.run([*script, "--friction-limit", "0.3"], capture_output=True, text=True, cwd=root, timeout=300)
    assert out.returncode in (0, 1), out.stderr  # 1: the one-generation gait missed its 2 s validation
    saved = tmp_path / "gait_1.10.json" if out.returncode == 0 else tmp_path / "rejected" / "gait_1.10.json"
    assert json.loads(saved.read_text())["info"]["problem"]["friction_limit"] == 0.3
    bad = subprocess.run([*script, "--friction-limit", "0"], capture_output=True, text=True, cwd=root, timeout=60)
    assert bad.returncode == 2 and "--friction-limit must be in [0.05, 2], got 0.0" in bad.stderr
