"""make demo's verdict (scripts/demo.py): each segment ok or off against the stated tolerance,
side by side, and one closing line that counts them."""

from __future__ import annotations

import pytest

from rabbit_policy.commands.demo import judge, within

pytestmark = pytest.mark.unit


def _report(means, reaches, fell=False):
    segments = [{"start": s, "end": e, "command": c, "mean_speed": m, "reach_time": r}
                for (s, e, c), m, r in zip([(0.0, 6.0, 0.8), (6.0, 13.0, 1.4)], means, reaches)]
    return {"segments": segments, "fell": fell, "stalled": False}


def test_a_segment_is_ok_within_the_tolerance_and_never_without_a_mean():
    assert within({"command": 1.2, "mean_speed": 1.175}, 0.03)
    assert not within({"command": 1.2, "mean_speed": 1.037}, 0.03)
    assert not within({"command": 1.2, "mean_speed": None}, 0.03)


def test_the_verdict_counts_each_controllers_segments_side_by_side():
    lines = judge({"learned": _report([0.837, 1.382], [3.16, 4.47]),
                   "classic": _report([0.779, None], [3.94, None], fell=True)}, 0.03)
    assert len(lines) == 2 + 2 + 1
    assert "0.837 off" in lines[2] and "0.779  ok" in lines[2] and "1.382  ok" in lines[3] and "never" in lines[3]
    assert lines[-1] == ("segments whose mean is within 0.03 m/s of the command: learned 1/2; classic 1/2 "
                         "(learned walked, classic fell)")
