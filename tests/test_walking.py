"""Closed-loop walking in real MuJoCo with the HZD controller core and the shipped gaits."""

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.experiment.setup import setup_walk, walk_gait

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = GaitLibrary.load()


def test_ten_second_walk_at_one_metre_per_second():
    result = walk_gait(LIBRARY.nearest(1.0), 10.0)
    assert not result.fell
    assert result.steps >= 15
    assert result.mean_speed == pytest.approx(1.0, rel=0.05)


def _trace(duration):
    """Walk and record per tick: phase, stance, step count, and MuJoCo foot contacts."""
    setup = setup_walk(LIBRARY.nearest(1.0))
    loop, c = setup.loop, setup.controller
    model, data = loop.model, loop.data
    feet = (model.geom("left_foot").id, model.geom("right_foot").id)
    rows = []

    def record(lp, _torques):
        touching = [False, False]
        for i in range(data.ncon):
            con = data.contact[i]
            for leg in (0, 1):
                if feet[leg] in (con.geom1, con.geom2):
                    touching[leg] = True
        rows.append((data.time, c.tau, int(c.stance), c.steps, c.touchdown, tuple(touching)))

    result = loop.run(duration, on_tick=record)
    assert not result.fell
    return rows


@pytest.fixture(scope="module")
def trace():
    return _trace(6.0)


def test_phase_is_monotonic_within_each_step(trace):
    by_step = {}
    for _, tau, _, steps, _, _ in trace:
        by_step.setdefault(steps, []).append(tau)
    assert len(by_step) >= 10
    for step, taus in by_step.items():
        drops = [a - b for a, b in zip(taus, taus[1:]) if b < a]
        assert not drops or max(drops) < 1e-3, f"phase went backwards in step {step}"
        if 0 < step < max(by_step):  # complete steps sweep the whole phase
            assert taus[0] < 0.1 and taus[-1] > 0.9


def test_exactly_one_stance_switch_per_step(trace):
    switches = [(t, stance) for t, _, stance, _, touchdown, _ in trace if touchdown]
    # Switches alternate legs and are a step period apart, never a chatter burst.
    for (t0, s0), (t1, s1) in zip(switches, switches[1:]):
        assert s0 != s1
        assert t1 - t0 > 0.2
    # Every switch is a real MuJoCo touchdown of the new stance foot ...
    for t, stance in switches:
        window = [touch for (time, *_rest, touch) in trace if t - 1e-9 <= time <= t + 0.005]
        assert any(touch[stance] for touch in window)
    # ... and every landing of a swing foot is one switch. A landing is a contact onset
    # after the foot was off the ground for a real swing (> 50 ms): a stance foot rolling
    # on its sphere loses contact for single ticks, which is not a step.
    landings = 0
    last_contact = {0: 0.0, 1: 0.0}
    previous = trace[0][5]
    for time, *_rest, touch in trace:
        for leg in (0, 1):
            if touch[leg]:
                if not previous[leg] and time - last_contact[leg] > 0.05:
                    landings += 1
                last_contact[leg] = time
        previous = touch
    assert landings == len(switches)


@pytest.mark.parametrize("gait", LIBRARY.gaits, ids=lambda g: f"{g.speed:.2f}")
def test_every_shipped_gait_walks_sixty_seconds_at_its_speed(gait):
    result = walk_gait(gait, 60.0)
    assert not result.fell
    assert abs(result.mean_speed - gait.speed) <= 0.05 * gait.speed


def test_library_covers_the_required_speeds():
    speeds = [round(s, 2) for s in LIBRARY.speeds]
    for v in (0.7, 0.8, 0.9, 1.0, 1.1):
        assert v in speeds
    for g in LIBRARY.gaits:
        for field in ("step_length", "step_period", "cost"):
            assert math.isfinite(getattr(g, field))
        assert g.info["validation"]["passed"]


def test_walk_script_json():
    out = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "walk.py"), "--controller", "hzd", "--speed", "0.9",
         "--duration", "5", "--json"],
        capture_output=True, text=True, timeout=120, check=True,
    )
    summary = json.loads(out.stdout)
    for key in ("fell", "steps", "mean_speed", "step_length", "step_period", "peak_torque"):
        assert key in summary
    assert summary["fell"] is False
    assert summary["gait_speed"] == pytest.approx(0.9)


def test_walk_script_rejects_bad_duration():
    out = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "walk.py"), "--duration", "-1"],
        capture_output=True, text=True, timeout=60,
    )
    assert out.returncode == 2
    assert "duration" in out.stderr
