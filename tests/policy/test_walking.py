"""Closed-loop walking in real MuJoCo with the HZD controller core and the shipped gaits,
on the one closed loop (``rabbit_policy.experiment``) and through ``scripts/walk.py``."""

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from rabbit_policy.experiment.loop import ClosedLoop, walk_gait
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import GaitCommand

pytestmark = pytest.mark.sim

ROOT = Path(__file__).resolve().parents[2]
LIBRARY = GaitLibrary.load()


def test_ten_second_walk_at_one_metre_per_second():
    result = walk_gait(LIBRARY.nearest(1.0), 10.0)
    assert not result.failed
    assert result.steps >= 15
    assert result.mean_speed(5.0) == pytest.approx(1.0, rel=0.05)


def _trace(duration):
    """Walk and record per tick: phase, stance, step count, and MuJoCo foot contacts."""
    gait = LIBRARY.nearest(1.0)
    loop = ClosedLoop(Scenario.constant(gait.speed), start=GaitCommand(gait.alpha, gait.kd), kp=gait.kp)
    c = loop.controller
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

    loop.observer = record
    assert not loop.run(duration)
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


@pytest.mark.slow
@pytest.mark.parametrize("gait", LIBRARY.gaits, ids=lambda g: f"{g.speed:.2f}")
def test_every_shipped_gait_walks_sixty_seconds_at_its_speed(gait):
    result = walk_gait(gait, 60.0)
    assert not result.failed
    assert abs(result.mean_speed(30.0) - gait.speed) <= 0.05 * gait.speed


def test_library_covers_the_required_speeds():
    speeds = [round(s, 2) for s in LIBRARY.speeds]
    for v in (0.7, 0.8, 0.9, 1.0, 1.1):
        assert v in speeds
    for g in LIBRARY.gaits:
        for field in ("step_length", "step_period", "cost"):
            assert math.isfinite(getattr(g, field))
        assert g.info["validation"]["passed"]


WALK_KEYS = {"fell", "stalled", "fall_time", "stall_time", "duration", "steps", "mean_speed", "peak_torque",
             "rejected", "touchdowns", "segments", "controller", "policy", "scenario", "real_time_factor",
             "wall_time", "completed", "error", "spec", "decisions_lost", "last_command_reached"}


def _walk_script(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "scripts" / "walk.py"), *args],
                          capture_output=True, text=True, timeout=180, check=check)


@pytest.mark.slow
def test_walk_script_json_has_the_same_keys_with_and_without_a_schedule():
    constant = json.loads(_walk_script("--controller", "classic", "--speed", "0.9", "--duration", "5", "--json").stdout)
    integral = json.loads(_walk_script("--speed", "0.9", "--duration", "1", "--speed-integral", "0.3", "--json").stdout)
    assert integral["policy"].startswith("classic/interpolate+integral0.3") and set(integral) == WALK_KEYS
    run = _walk_script("--controller", "hzd", "--speed-schedule", "0:0.9,2:1.0", "--duration", "5", "--json",
                       check=False)
    scheduled = json.loads(run.stdout)
    assert run.returncode == (4 if scheduled["last_command_reached"] is False else 0)  # exit 4: never reached
    assert set(constant) == set(scheduled) == WALK_KEYS
    assert constant["controller"] == scheduled["controller"] == "classic"
    assert constant["fell"] is False and constant["stalled"] is False
    assert constant["mean_speed"] == pytest.approx(0.9, abs=0.05)
    assert len(constant["touchdowns"]) == constant["steps"] >= 7
    assert [s["command"] for s in scheduled["segments"]] == [0.9, 1.0]
    for segment in scheduled["segments"]:
        assert set(segment) == {"command", "start", "end", "mean_speed", "reach_time"}


def test_walk_script_reports_a_fall_as_json_null_not_nan():
    out = _walk_script("--controller", "classic", "--speed", "1.0", "--duration", "6", "--push", "1:-400:0.1",
                       "--json", check=False)
    assert out.returncode == 1
    assert "NaN" not in out.stdout
    summary = json.loads(out.stdout)
    assert summary["fell"] or summary["stalled"]
    assert summary["mean_speed"] is None


def test_the_speed_integral_removes_the_steady_error_of_the_drives_model():
    """Classic HZD walks the ``drives`` model (rotor inertia, joint friction) about 0.19 m/s
    too slow at 1.0 m/s; Westervelt's event-based integral on the command removes it."""
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.spec.make import make_policy
    from rabbit_sim.physics.model import ModelOptions

    scenario = Scenario.constant(1.0, model=ModelOptions("drives"))
    plain = walk(make_policy("classic"), scenario, 20.0)
    integral = walk(make_policy("classic", speed_integral=0.3), scenario, 20.0)
    assert not plain.failed and plain.mean_speed(10.0) < 0.9
    assert not integral.failed and integral.mean_speed(10.0) == pytest.approx(1.0, abs=0.03)



@pytest.mark.slow
def test_the_windup_decay_leaves_a_constant_command_alone_and_takes_the_overshoot_out_of_a_change():
    """The learned network's integral winds up on the lag behind a new command (0.8 -> 1.4 m/s:
    about 0.07 m/s too fast 5-10 s later without the windup decay); with it the overshoot is
    less than half that, and a walk at a constant command is the same walk bit for bit."""

    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.runtime.memory import SpeedMemory
    from rabbit_policy.spec.make import make_policy
    from rabbit_policy.runtime.speed_integral import WindupDecay

    plain, decaying = make_policy("learned"), make_policy("learned")
    plain.memory = SpeedMemory(plain.memory.config.with_integral(windup_decay=None, feedforward=None))  # the network's own
    decaying.memory = SpeedMemory(decaying.memory.config.with_integral(windup_decay=WindupDecay(), feedforward=None))
    constant = Scenario.constant(1.1)
    assert (walk(plain, constant, 8.0).hip_x == walk(decaying, constant, 8.0).hip_x).all()
    change = Scenario(schedule=((0.0, 0.8), (6.0, 1.4)))
    late = [walk(policy, change, 16.0).mean_speed(11.0, 16.0) - 1.4 for policy in (plain, decaying)]
    assert late[0] > 0.05 and abs(late[1]) < 0.5 * late[0], late


@pytest.mark.slow
def test_the_integral_feedforward_start_takes_the_start_transient_out():
    """The network shipped before (the tests' checkpoint, with the rules it shipped with) needs I
    of about -0.25 m to walk at 1.0 m/s (it walks fast at
    I = 0), so a walk that starts its integral at 0 is about 0.03 m/s too fast 3-6 s in (0.04
    before the policy blend); with the table measured on it (steady_integrals) and ``start``,
    the integral starts at its steady value and the walk is within 0.02, and within half the
    other's error. The table is each speed's mean I; a policy without an integral, or
    one that does not walk at a speed, has none (one line)."""
    from dataclasses import replace

    from rabbit_policy.evaluation.steady_integral import steady_integral, steady_integrals
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.runtime.memory import SpeedMemory
    from rabbit_policy.runtime.policies import NetworkPolicy
    from rabbit_policy.spec.make import make_policy

    from checkpoints import SHIPPED_BEFORE

    plain, fed = make_policy("learned", policy_file=SHIPPED_BEFORE), make_policy("learned", policy_file=SHIPPED_BEFORE)
    plain.memory = SpeedMemory(plain.memory.config.with_integral(feedforward=None))
    table = steady_integrals(plain, (0.95, 1.0, 1.05))
    assert table.values[1] < -0.15 and table.values == steady_integrals(fed, (0.95, 1.0, 1.05)).values
    fed.memory = SpeedMemory(fed.memory.config.with_integral(feedforward=replace(table, start=True)))
    early = [walk(policy, Scenario.constant(1.0), 6.0).mean_speed(3.0, 6.0) - 1.0 for policy in (plain, fed)]
    assert early[0] > 0.02 and abs(early[1]) < min(0.02, early[0] / 2), early
    with pytest.raises(ValueError, match="did not walk"):
        steady_integral(plain, 0.5, duration=3.0, settle=1.0)
    with pytest.raises(ValueError, match="settle"):
        steady_integral(plain, 1.0, duration=3.0, settle=3.0)
    with pytest.raises(ValueError, match="keeps no speed integral"):
        steady_integrals(NetworkPolicy(plain.forward, "no integral"), (1.0, 1.1))


@pytest.mark.parametrize("args, word", [
    (("--duration", "-1"), "duration"),
    (("--speed-integral", "-1"), "speed-integral"),
    (("--speed", "nan"), "speed"),
    (("--schedule", "1:0.8"), "t = 0"),
    (("--push", "2:50"), "push"),
    (("--friction", "0"), "friction"),
    (("--controller", "best"), "controller"),
])
def test_walk_script_bad_arguments_are_one_line_and_exit_2(args, word):
    out = _walk_script(*args, check=False)
    assert out.returncode == 2
    assert len(out.stderr.strip().splitlines()) == 1 and word in out.stderr


@pytest.mark.slow
def test_walk_script_model_errors_reach_the_scenario():
    out = _walk_script("--controller", "rl", "--speed", "1.0", "--duration", "3", "--model", "drives",
                       "--friction", "0.6", "--torso-mass-scale", "1.1", "--torque-delay", "0.002",
                       "--push", "1:20:0.1", "--json", check=False)
    summary = json.loads(out.stdout)
    assert set(summary) == WALK_KEYS and summary["controller"] == "learned"
    assert summary["scenario"]["model"] == {"variant": "drives", "friction": 0.6, "torso_mass_scale": 1.1}
    assert summary["scenario"]["torque_delay_s"] == 0.002 and summary["scenario"]["pushes"] == "1.0:20.0:0.1"
    assert out.returncode == (1 if summary["fell"] or summary["stalled"] else 0)


def test_walk_writes_an_offscreen_video_of_the_walk(tmp_path):
    """``walk.py --video FILE.gif`` on a machine without a display: MuJoCo's offscreen
    renderer picked by itself, 25 frames per s of sim time, no traceback at exit; any other
    suffix or a missing directory is one line, exit 2, before the walk."""
    import os

    from PIL import Image

    headless = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL")}
    video = tmp_path / "walk.gif"
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / "walk.py"), "--duration", "1", "--video", str(video)],
                         capture_output=True, text=True, timeout=300, env=headless)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "Traceback" not in out.stderr
    with Image.open(video) as gif:
        assert gif.size == (320, 240) and gif.n_frames == 25
    for bad in (str(tmp_path / "walk.mp4"), str(tmp_path / "missing" / "walk.gif")):
        refused = _walk_script("--duration", "1", "--video", bad, check=False)
        assert refused.returncode == 2 and refused.stderr.count("\n") == 1 and "--video" in refused.stderr


def test_times_are_on_the_tick_grid_whatever_decimals_a_schedule_and_duration_have():
    """Issue 40's case: a change and a duration off the ms grid. The walk runs the duration's
    whole ticks and ends on the grid (4.132 s, not 4.131999...), the last segment ends there
    too, so its mean speed is reported; touchdowns and reach times are on the ns grid."""
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.spec.make import make_policy

    duration = 4.132268422788288
    result = walk(make_policy("classic"), Scenario(schedule=((0.0, 0.9), (2.132268422788288, 1.1))), duration)
    summary = result.summary()
    assert summary["duration"] == 4.132 and result.end_time == 4.132
    last = summary["segments"][-1]
    assert last["end"] == 4.132 and last["mean_speed"] is not None
    assert all(round(t, 9) == t for t in result.times[:50]) and all(round(td.time, 9) == td.time
                                                                       for td in result.touchdowns)
    assert all(row["reach_time"] is None or round(row["reach_time"], 9) == row["reach_time"]
               for row in summary["segments"][:1])


def _times(report: dict) -> list[tuple[str, float]]:
    """Every time a walk.py JSON report gives (s): durations, failure times, segment bounds,
    reach times and touchdowns."""
    found = [(k, report[k]) for k in ("duration", "fall_time", "stall_time") if report[k] is not None]
    found += [("touchdown", t) for t in report["touchdowns"]]
    for row in report["segments"]:
        found += [(k, row[k]) for k in ("start", "end", "reach_time") if row[k] is not None]
    return found


@pytest.mark.slow
def test_walk_json_times_are_on_the_ms_grid_for_off_grid_schedules_and_durations():
    """Issue 57's case (a reach time of 2.0389999999999997) and changes and durations off the
    ms grid: every reported time is a whole number of ms, and a change takes effect at the
    first tick at or after its time (6.0004 s walks as 6.001 s)."""
    off = json.loads(_walk_script("--controller", "learned", "--speed-schedule", "0:1.5,6.0004:0.8", "--duration",
                                  "13.9996", "--json").stdout)
    on = json.loads(_walk_script("--controller", "learned", "--speed-schedule", "0:1.5,6.001:0.8", "--duration",
                                 "14", "--json").stdout)
    plain = json.loads(_walk_script("--controller", "learned", "--speed-schedule", "0:1.5,6:0.8", "--duration", "14",
                                    "--json").stdout)
    for report in (off, on, plain):
        times = _times(report)
        assert len(times) > 20 and [(k, t) for k, t in times if t != round(t, 3)] == []
        assert all(row["reach_time"] is not None for row in report["segments"])
    assert off["segments"] == on["segments"] and off["touchdowns"] == on["touchdowns"]
    assert off["segments"][1]["start"] == 6.001


def test_a_reach_time_counts_from_the_tick_the_change_takes_effect():
    """A change at 2.0005 s takes effect at 2.001 s: its reach (the robustness check's, asked
    with the nominal time) is counted from there, in whole ticks."""
    from rabbit_policy.experiment.loop import walk
    from rabbit_policy.spec.make import make_policy

    result = walk(make_policy("classic"), Scenario(schedule=((0.0, 0.9), (2.0005, 1.1))), 7.0)
    assert result.scenario.schedule[1][0] == 2.001
    nominal, effective = result.reach_time(2.0005, 7.0, 1.1), result.reach_time(2.001, 7.0, 1.1)
    assert nominal is not None and nominal == effective == round(nominal, 3)
