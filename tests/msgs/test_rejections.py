"""RejectionLog: every rejection counted, one line per kind per period, the rest said later."""

from __future__ import annotations

import pytest

from rabbit_msgs_py.rejections import RejectionLog

pytestmark = pytest.mark.unit


def test_one_line_per_kind_per_period_and_the_unlogged_ones_said():
    now = [0.0]
    log = RejectionLog(period=1.0, clock=lambda: now[0])
    lines = [log.line("kd", "bad kd") for _ in range(500)]
    assert lines[0] == "bad kd" and lines[1:] == [None] * 499
    assert log.line("alpha", "bad alpha") == "bad alpha"  # another kind: its own line
    now[0] = 0.5
    assert log.flush() == []  # within the period: nothing yet
    now[0] = 1.2
    assert log.line("kd", "bad kd") == ("bad kd (and 499 more of kind 'kd' in the last 1.2 s, not logged: counted by "
                                        "kind, their texts may differ)")
    log.line("kd", "bad kd")
    now[0] = 2.5
    assert log.flush() == ["1 more of kind 'kd' after the last one logged, in the last 1.3 s"]
    assert log.flush() == []
    assert log.counts == {"kd": 502, "alpha": 1}
