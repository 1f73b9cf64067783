"""The ROS-free loop past three minutes of sim time (issue 76): every tick's time, a schedule
change, a segment's window and its mean come from the tick count, not MuJoCo's float sum of
1 ms steps (which leaves the ns grid at tick 180,963; ``walk.py --duration 400`` once gave the
last segment no mean). Provoked directly by starting the loop's clock at that tick; the
400 s and 600 s walks of the issue run in the slow tier."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import LibraryPolicy

ROOT = Path(__file__).resolve().parents[2]
DRIFT_TICK = 180_963


def _on_ms_grid(times: np.ndarray) -> bool:
    """Every time (s) is the float nearest a whole ms."""
    ms = np.round(times * 1e3).astype(np.int64)
    return bool(np.array_equal(times, ms * 1_000_000 / 1e9))


@pytest.mark.unit
def test_a_loop_whose_clock_starts_past_the_drift_tick_keeps_whole_ms_and_decides_on_them():
    loop = ClosedLoop(Scenario.constant(1.0), LibraryPolicy(GaitLibrary.load()), start_tick=DRIFT_TICK)  # placed at 180.963 s
    t = 0.0
    for _ in range(DRIFT_TICK):
        t += 0.001
    loop.data.time = t  # and MuJoCo's drifted float sum beside it
    loop.run(2.0)
    result = loop.result()
    assert len(result.times) == 2000 and _on_ms_grid(result.times)
    assert result.times[0] == (DRIFT_TICK + 1) / 1000 and result.times[-1] == (DRIFT_TICK + 2000) / 1000
    assert all(_on_ms_grid(np.array([td.time])) for td in result.touchdowns) and result.touchdowns
    assert all(_on_ms_grid(np.array([d.time])) for d in result.decisions) and result.decisions


@pytest.mark.slow
@pytest.mark.sim
@pytest.mark.parametrize("duration", [400, 600])
def test_walk_py_gives_every_segment_its_mean_at_400_and_600_s(duration):
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / "walk.py"), "--controller", "classic",
                          "--speed-schedule", "0:1.0,385:1.3", "--duration", str(duration), "--json"],
                         capture_output=True, text=True, timeout=300, check=True)
    report = json.loads(out.stdout)
    first, last = report["segments"]
    assert first["mean_speed"] == pytest.approx(1.0, abs=0.03)
    assert last["mean_speed"] == pytest.approx(1.3, abs=0.03) and last["reach_time"] is not None
    assert report["duration"] == float(duration)
