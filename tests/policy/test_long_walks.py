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


@pytest.mark.unit
def test_a_report_of_a_run_whose_policy_stopped_deciding_is_not_complete():
    from rabbit_policy.bringup.config import StackConfig
    from rabbit_policy.bringup.supervisor import RunReport
    from rabbit_policy.experiment.result import exit_status

    report = RunReport.not_started(StackConfig(duration=1.0, schedule=((0.0, 1.0),)), "x")
    report.completed, report.error = True, None
    report.take_controller_counts({"rejected_gaits": 0, "decisions_timed_out": 1, "policy_silences": 9})
    summary = report.summary()
    assert summary["decisions_lost"] == 10 and summary["completed"] is False
    assert "stopped deciding" in summary["error"] and exit_status(summary) == 3


@pytest.mark.unit
def test_the_exit_status_says_fell_incomplete_or_never_reached():
    from rabbit_policy.experiment.result import exit_status

    ok = {"fell": False, "stalled": False, "completed": True, "last_command_reached": True}
    assert exit_status(ok) == 0 and exit_status({**ok, "last_command_reached": None}) == 0  # no whole step to judge
    assert exit_status({**ok, "last_command_reached": False}) == 4
    assert exit_status({**ok, "completed": False}) == 3 and exit_status({**ok, "fell": True}) == 1


@pytest.mark.sim
def test_a_last_command_never_reached_is_said():
    from rabbit_policy.experiment.loop import walk

    # 0.7 -> 1.5 m/s 0.6 s before the end: whole steps in the segment, none within 0.05 m/s yet
    scenario = Scenario(schedule=((0.0, 0.7), (3.0, 1.5)))
    result = walk(LibraryPolicy(GaitLibrary.load()), scenario, 4.2)
    assert result.summary()["last_command_reached"] is False
    assert walk(LibraryPolicy(GaitLibrary.load()), Scenario.constant(1.0), 0.3).last_command_reached() is None
