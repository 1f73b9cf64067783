"""WalkResult.tracking_scores: the evaluation's reach and settle rules as graded scores (the
training reward ``evaluation``), on walks of the real closed loop."""

from __future__ import annotations

import pytest

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.result import REACH_WITHIN, SETTLE_TOLERANCE
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.spec import load_packaged

pytestmark = pytest.mark.sim


def test_scores_follow_the_segments_reach_times_and_mean_speed_errors():
    result = walk(load_packaged("classic"), Scenario(schedule=((0.0, 0.8), (4.0, 1.2))), 10.0)
    first, second = result.segments()
    reach, settle = result.tracking_scores()
    assert second["reach_time"] is not None and second["reach_time"] <= REACH_WITHIN
    assert reach == pytest.approx(1.0 - second["reach_time"] / REACH_WITHIN)  # the first segment is no change
    expected = sum(1.0 / (1.0 + ((s["mean_speed"] - s["command"]) / SETTLE_TOLERANCE) ** 2) for s in (first, second))
    assert settle == pytest.approx(expected) and 0.0 < settle <= 2.0


def test_a_walk_that_falls_or_stalls_scores_nothing():
    result = walk(load_packaged("classic"), Scenario.constant(1.0, pushes=(Push(2.0, -400.0, 0.1),)), 6.0)
    assert result.failed and result.tracking_scores() == (0.0, 0.0)
