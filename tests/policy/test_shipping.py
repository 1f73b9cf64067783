"""evaluation/shipping.py: the screen that says whether a retrained learned controller beats
the one it was trained from (the paper's push scenarios, the push grid, the verdict)."""

from __future__ import annotations

import pytest

from rabbit_policy.evaluation.push_recovery import classic_margin
from rabbit_policy.evaluation.robustness import RobustnessConfig, phase_times, push_survived
from rabbit_policy.evaluation.shipping import MarginGrid, margin_grid, screen_rank, verdict
from rabbit_policy.spec import load_packaged


def measured(failures=0, large="walked", forward=100, backward=100, small="walked") -> dict:
    outcome = {name: {"outcome": o} for name, o in
               (("small_forward", small), ("small_backward", "walked"), ("large_backward", large))}
    return {"failures": failures, "scenarios": outcome,
            "margin_grid": {"forward": forward, "backward": backward, "of": {"forward": 160, "backward": 160}}}


@pytest.mark.unit
def test_the_verdict_needs_the_checks_large_backward_more_forward_and_as_many_backward_pushes():
    start = measured(large="fell", forward=122, backward=153)
    assert verdict(measured(forward=123, backward=153), start) == (True, [])
    for candidate, reason in ((measured(failures=1, forward=130, backward=160), "fails 1 acceptance checks"),
                              (measured(large="fell", forward=130, backward=160), "large_backward: fell"),
                              (measured(small="stalled", forward=130, backward=160), "small_forward: stalled"),
                              (measured(forward=122, backward=160), "forward pushes 122 of 160, the start 122"),
                              (measured(forward=130, backward=152), "backward pushes 152 of 160, the start 153")):
        ships, why = verdict(candidate, start)
        assert not ships and len(why) == 1 and why[0].startswith(reason), why
    ranked = sorted([measured(forward=120), measured(large="fell", forward=150), measured(forward=125),
                     measured(failures=1, forward=160)], key=screen_rank)
    assert [(m["failures"], m["margin_grid"]["forward"]) for m in ranked] == [(0, 125), (0, 120), (0, 150), (1, 160)]


@pytest.mark.unit
def test_the_grid_scales_its_pushes_to_classics_margin():
    grid = MarginGrid()
    assert grid.impulses(1.0, "forward") == [round(1.1 * 16), round(1.4 * 16)]
    assert grid.impulses(1.0, "backward") == [-round(1.5 * 9), -round(2.0 * 9)]
    assert grid.impulses(1.05, "forward") == [round(1.1 * classic_margin(1.05, 1)), round(1.4 * classic_margin(1.05, 1))]
    assert grid.pushes_per_direction("forward") == 5 * 2 * 16
    with pytest.raises(ValueError):
        MarginGrid(phases=0)


@pytest.mark.sim
def test_the_grid_counts_each_push_as_the_margins_rule_judges_it():
    grid = MarginGrid(speeds=(1.05,), forward=(1.1, 2.0), backward=(1.5,), phases=2, horizon=2.0)
    policy = load_packaged("classic")
    counted = margin_grid(policy, grid)
    config = RobustnessConfig(push_duration=grid.push_duration, push_horizon=grid.horizon)
    times = phase_times(policy, 1.05, grid.settle, [0.0, 0.5])
    expected = {d: sum(push_survived((policy, 1.05, t, i, config)) for i in grid.impulses(1.05, d) for t in times)
                for d in ("forward", "backward")}
    assert {d: counted[d] for d in expected} == expected
    assert counted["of"] == {"forward": 4, "backward": 2}
    assert counted["per_speed"] == [{"speed": 1.05, **expected}]
