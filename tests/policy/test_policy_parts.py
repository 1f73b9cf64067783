"""ROS-free parts of the stack: the speed window, speed clamping, schedule parsing, the
controller's stance inference, gait queuing and alpha bounds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rabbit_msgs_py.decision_ticks import PER_STEP

from rabbit_hzd_controller.controller import HZDController, Leg, infer_stance
from rabbit_hzd_controller.gait_state import state_on_gait
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import LibraryPolicy, PolicyUnavailable
from rabbit_policy.spec.make import make_policy
from rabbit_policy.runtime.commands import clamp_speed
from rabbit_policy.runtime.speed_window import SpeedWindow
from rabbit_policy.experiment.scenario import Push, Scenario, parse_pushes, parse_schedule
from rabbit_policy.bringup.config import StackConfig, ros_arguments

pytestmark = pytest.mark.unit

MS = 1_000_000


def test_speed_window_averages_up_to_a_stamp():
    window = SpeedWindow(size=3)
    for i, v in enumerate([1.0, 2.0, 3.0, 4.0, 5.0]):
        window.add(i * MS, v, desired_speed=3.0)
    obs = window.observation(3.0)
    assert (obs.mean_speed, obs.mean_error) == (4.0, -1.0)  # last three: 3, 4, 5
    obs = window.observation(3.0, stamp_ns=2 * MS)  # samples 1, 2, 3 (stamps 0..2)
    assert (obs.mean_speed, obs.mean_error) == (2.0, 1.0)
    assert window.observation(1.0, stamp_ns=-1).as_tuple() == (1.0, 1.0, 0.0)
    window.add(0, 9.0, 3.0)  # time went back: a reset starts afresh
    assert len(window) == 1 and window.observation(3.0).mean_speed == 9.0
    with pytest.raises(ValueError):
        window.add(MS, math.nan, 1.0)


def test_speed_window_keeps_the_newest_two_windows_and_its_means_are_correctly_rounded():
    """The window finds its samples by bisection and sums them with fsum: the mean is the
    exact sum rounded once, over n (so it does not depend on the order or on what came before),
    over at most ``size`` samples among the newest ``2 * size``, however many were added."""
    from fractions import Fraction

    rng = np.random.default_rng(5)
    window = SpeedWindow(size=50)
    speeds = rng.uniform(0.0, 2.0, 1000) * 10.0 ** rng.integers(-8, 2, 1000)  # badly scaled: order matters
    for i, v in enumerate(speeds):
        window.add(i * MS, float(v), desired_speed=1.0)
        assert len(window) == min(i + 1, 100)
    for stamp, since in [(None, None), (999 * MS, 975 * MS), (960 * MS, None), (930 * MS, 920 * MS)]:
        end = 1000 if stamp is None else stamp // MS + 1
        start = max(end - 50, 900, (since // MS + 1) if since is not None else 0)
        exact = sum(Fraction(float(v)) for v in speeds[start:end])
        assert window.observation(1.0, stamp, since).mean_speed == float(exact) / (end - start)
    assert window.observation(1.0, 880 * MS).as_tuple() == (1.0, 1.0, 0.0)  # older than the newest 100: dropped


def test_exact_sum_is_math_fsum_bit_for_bit():
    """The compiled correctly rounded sum equals math.fsum (one correctly rounded value, whatever
    the algorithm) on badly scaled, cancelling and tie-making data; non-finite input falls back
    to fsum's own rules."""
    from rabbit_policy.runtime.exact_sum import exact_sum

    rng = np.random.default_rng(11)
    cases = [np.zeros(0), np.array([1.0]), np.array([1e100, 1.0, -1e100]), np.array([1.0, 1e-16, 1e-16]),
             np.array([2.0 ** 53, 1.0, 2.0 ** -60]), np.array([2.0 ** 53, 1.0, -(2.0 ** -60)]),  # ties and near-ties
             np.array([0.1] * 10)]
    for _ in range(300):
        n = int(rng.integers(1, 800))
        values = rng.uniform(-1.0, 1.0, n) * 10.0 ** rng.integers(-20, 20, n)
        values = np.concatenate([values, -values[: n // 2] * (1 + 1e-15)])  # heavy cancellation
        cases.append(rng.permutation(values))
    for values in cases:
        got, want = exact_sum(values), math.fsum(values.tolist())
        assert got == want or (math.isnan(got) and math.isnan(want)), values
    assert exact_sum(np.array([math.inf, 1.0])) == math.inf
    with pytest.raises(OverflowError):  # as fsum: an intermediate overflow
        exact_sum(np.array([1e308, 1e308, -1e308]))


def test_clamp_speed():
    assert clamp_speed(1.2, 0.7, 1.5) == 1.2
    assert clamp_speed(9.0, 0.7, 1.5) == 1.5 and clamp_speed(-1.0, 0.7, 1.5) == 0.7
    for bad in (math.nan, math.inf):
        with pytest.raises(ValueError):
            clamp_speed(bad, 0.7, 1.5)


def test_schedule_and_push_parsing():
    assert parse_schedule("0:0.8,10:1.2,20:1.0") == ((0.0, 0.8), (10.0, 1.2), (20.0, 1.0))
    assert parse_pushes("4:-80:0.2,2:60:0.1") == (Push(2.0, 60.0, 0.1), Push(4.0, -80.0, 0.2))
    for bad in ("0:0.8,x", "0:nan", "-1:1.0"):
        with pytest.raises(ValueError):
            parse_schedule(bad)
    with pytest.raises(ValueError):
        parse_pushes("1:50:0")
    with pytest.raises(ValueError):
        StackConfig(duration=5.0, schedule=((1.0, 0.8),))
    with pytest.raises(ValueError):
        StackConfig(duration=5.0, schedule=((0.0, 0.8), (0.0, 1.0)))
    # one spacing rule on every path (walk.py's Scenario, run_stack's StackConfig): 0.1 s
    crowded = tuple((round(k * 0.0002, 4), 0.8 + 0.1 * (k % 2)) for k in range(8000))
    for build in (lambda s: Scenario(schedule=s), lambda s: StackConfig(duration=5.0, schedule=s)):
        with pytest.raises(ValueError, match="at least 0.1 s apart"):
            build(crowded)
        build(((0.0, 0.8), (0.1, 1.0)))  # exactly the spacing is fine


def test_a_layout_is_one_of_three_and_a_cpu_meter_counts_per_tick():
    import os

    from rabbit_policy.bringup.config import LAYOUTS
    from rabbit_policy.bringup.cpu import CpuMeter, process_cpu_seconds

    assert StackConfig(duration=1.0, schedule=((0.0, 1.0),)).layout == "composed" == LAYOUTS[0]
    with pytest.raises(ValueError, match="layout must be one of composed, separate, in-process"):
        StackConfig(duration=1.0, schedule=((0.0, 1.0),), layout="components")
    meter = CpuMeter({"me": os.getpid()})
    assert meter.per_tick_us(5_000_000) is None and not meter.started  # not started: nothing measured
    meter.start(1_000_000)
    spent = process_cpu_seconds(os.getpid())
    while process_cpu_seconds(os.getpid()) < spent + 0.05:  # burn at least 50 ms of CPU
        pass
    per_tick = meter.per_tick_us(1_000_000 + 100 * 1_000_000)  # over 100 ticks
    assert per_tick["me"] >= 0.05 / 100 * 1e6 and per_tick["total"] == per_tick["me"]
    assert meter.per_tick_us(1_000_000) is None  # no ticks
    assert process_cpu_seconds(2 ** 30) is None  # no such process


def test_ros_arguments():
    assert ros_arguments({"mode": "lockstep", "stop_time": 5.0, "start_paused": True, "gait_dir": ""}) == [
        "--ros-args", "-p", "mode:=lockstep", "-p", "stop_time:=5.0", "-p", "start_paused:=true",
    ]


@pytest.mark.parametrize("stance", [Leg.LEFT, Leg.RIGHT])
@pytest.mark.parametrize("tau", [0.0, 0.3, 0.7])
def test_infer_stance_on_the_gait(stance, tau):
    gait = GaitLibrary.load().nearest(1.0)
    q, _ = state_on_gait(gait.alpha, gait.speed, tau=tau, stance=stance)
    assert infer_stance(q) is stance


def test_alpha_outside_joint_waypoint_bounds_is_rejected():
    gait = GaitLibrary.load().nearest(1.0)
    controller = HZDController(gait.alpha, gait.kd)
    with pytest.raises(ValueError, match="outside the bounds"):
        controller.set_alpha([a + 2.0 for a in gait.alpha])
    with pytest.raises(ValueError):
        controller.queue_kd(1e6)
    assert controller.pending_alpha is None and controller.pending_kd is None


def test_policies():
    library = GaitLibrary.load()
    from rabbit_policy.runtime.policies import CLASSIC_DECISION_PERIOD, PeriodicPolicy, decision_period
    from rabbit_policy.runtime.speed_window import Observation

    policy = make_policy("classic", mode="interpolate", decision=PER_STEP)
    assert isinstance(policy, LibraryPolicy) and decision_period(policy) == 0
    periodic = make_policy("classic")  # the default: calibrated interpolation, every 20 ticks
    assert isinstance(periodic, PeriodicPolicy) and decision_period(periodic) == CLASSIC_DECISION_PERIOD
    assert periodic.policy.mode == "interpolate"
    for bad in (-1, 2.5, True, None):
        with pytest.raises(ValueError, match="DecisionTiming"):
            make_policy("classic", decision=bad)


    command = policy.act(Observation(1.05, 0.9, 0.15))
    expected = library.interpolate(1.05)
    assert command.alpha == expected.alpha and command.kd == expected.kd
    with pytest.raises(PolicyUnavailable, match="does not exist"):
        make_policy("learned", policy_file="/nonexistent/policy.pt")
    with pytest.raises(ValueError):
        make_policy("classic", mode="best")


def test_a_decision_timing_is_parsed_formatted_and_checked_in_one_place():
    from rabbit_msgs_py.decision_ticks import OWN, DecisionTiming

    assert [DecisionTiming.parse(t) for t in ("own", "-1", "step", "0", "20", " 20 ")] == \
        [OWN, OWN, PER_STEP, PER_STEP, DecisionTiming(20), DecisionTiming(20)]
    assert [str(t) for t in (OWN, PER_STEP, DecisionTiming(20))] == ["own", "step", "20"]
    assert [t.param for t in (OWN, PER_STEP, DecisionTiming(20))] == [-1, 0, 20]  # the node parameter
    assert DecisionTiming.parse(-1) == OWN and DecisionTiming.parse(DecisionTiming(7).param) == DecisionTiming(7)
    assert OWN.resolve(20) == 20 and PER_STEP.resolve(20) == 0
    for bad in ("-2", "2.5", "sometimes", ""):
        with pytest.raises(ValueError, match="own, step or a whole number of ticks"):
            DecisionTiming.parse(bad)
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError):
            DecisionTiming(bad)


def test_the_speed_integral_accumulates_the_error_within_its_bound_and_starts_afresh():
    from rabbit_policy.runtime.speed_integral import IntegralConfig, SpeedIntegral, decision_dt, integral_limit
    from rabbit_policy.runtime.speed_window import Observation

    integral = SpeedIntegral(IntegralConfig(limit=0.4, dt=0.02))
    assert integral.update(0.1, 1.0) == pytest.approx(0.002)  # 0.1 m/s x 0.02 s
    for _ in range(10_000):
        integral.update(0.1, 1.0)
    assert integral.value == 0.4  # held at the bound (anti-windup) ...
    assert integral.update(-0.1, 1.0) == pytest.approx(0.398)  # ... so it unwinds at the first opposite error
    integral.reset()
    assert integral.value == 0.0
    assert decision_dt(20) == 0.02 and decision_dt(0) == 0.6
    assert integral_limit(0.5) == pytest.approx(0.4)  # 0.5 1/s x 0.4 m = the 0.2 m/s offset bound
    for bad in ({"limit": -1.0}, {"dt": math.nan}):
        with pytest.raises(ValueError, match="speed integral"):
            IntegralConfig(**({"limit": 0.2, "dt": 0.02} | bad))
    with pytest.raises(ValueError, match="speed integral"):
        integral_limit(0.0)

    library = GaitLibrary.load()
    policy = make_policy("classic", speed_integral=0.5).policy  # every 20 ticks: dt 0.02 s
    assert policy.name == "classic/interpolate+integral0.5"
    first = policy.act(Observation(1.0, 0.9, 0.1))  # the gait for 1.001 m/s
    assert first.alpha == library.interpolate(1.0 + 0.5 * 0.1 * 0.02).alpha
    for _ in range(10_000):
        policy.act(Observation(1.0, 0.9, 0.1))
    assert policy.act(Observation(1.0, 0.9, 0.1)).alpha == library.interpolate(1.2).alpha  # held at +0.2 m/s
    for _ in range(10_000):
        policy.act(Observation(1.4, 1.3, 0.1))
    assert policy.integral.value == pytest.approx(0.2)  # 1.4 + 0.5 x 0.2 = 1.5, the library's fastest gait
    policy.reset()
    assert policy.act(Observation(1.0, 1.0, 0.0)).alpha == library.interpolate(1.0).alpha
    assert make_policy("classic", decision=PER_STEP, speed_integral=0.5).integral.config.dt == 0.6
    assert make_policy("classic").policy.integral is None  # off by default: the paper's baseline
    for bad in (-0.1, math.inf, math.nan):
        with pytest.raises(ValueError, match="speed integral gain"):
            make_policy("classic", speed_integral=bad)
    with pytest.raises(ValueError, match="classic controller's"):
        make_policy("learned", speed_integral=0.5)


def test_the_speed_integral_is_held_where_the_gait_would_leave_the_library_range():
    """With a gain and the library's speed range, I stays where v_d + gain * I is inside it."""
    from rabbit_policy.runtime.memory import MemoryConfig
    from rabbit_policy.runtime.speed_integral import IntegralConfig, SpeedIntegral

    ranged = SpeedIntegral(IntegralConfig(limit=1.0, dt=1.0, gain=0.5, speed_range=(0.7, 1.5)))
    assert ranged.update(0.1, 1.0) == pytest.approx(0.1)
    assert ranged.update(1.0, 1.0) == pytest.approx(1.0)  # 1.0 + 0.5 x 1.0 = 1.5: the top of the range
    assert ranged.update(0.1, 1.4) == pytest.approx(0.2)  # the command rose: I held at (1.5 - 1.4) / 0.5
    assert ranged.update(-0.5, 0.7) == pytest.approx(0.0)  # at the bottom, I cannot go below 0
    assert ranged.update(0.1, 0.7) == pytest.approx(0.1)
    free = SpeedIntegral(IntegralConfig(limit=1.0, dt=1.0))  # no range: the memory of older checkpoints
    assert free.update(0.9, 1.5) == pytest.approx(0.9)

    memory = MemoryConfig.for_features("memory", 20, 0.3, (0.7, 1.5))  # a residual's base gait: held in range
    assert memory.integral.speed_range == (0.7, 1.5)
    assert MemoryConfig.from_dict({**memory.to_dict(), "speed_range": [0.7, 1.5]}) == memory  # as a checkpoint holds it
    assert MemoryConfig.from_dict({"dt": 0.02, "limit": 0.5}).integral.speed_range is None  # checkpoints from before the gate
    with pytest.raises(ValueError, match="speed range"):
        MemoryConfig.for_features("memory", 20, 0.3)
    for bad in ({"speed_range": (1.5, 0.7), "gain": 0.5}, {"speed_range": (0.7, 1.5)},
                {"speed_range": (0.7, math.nan), "gain": 0.5}):
        with pytest.raises(ValueError, match="speed integral"):
            IntegralConfig(**({"limit": 0.2, "dt": 0.02} | bad))


def test_the_speed_integral_with_a_band_holds_on_large_errors_and_integrates_small_ones():
    """Conditional integration: |v_d - v̄| >= band (a transient: a hip lagging a new command,
    a push) leaves I where it is; smaller errors integrate as without a band. Error
    saturation: with a clip, a large error integrates at the clip's rate."""
    from rabbit_policy.runtime.memory import MemoryConfig
    from rabbit_policy.runtime.speed_integral import IntegralConfig, SpeedIntegral

    banded = SpeedIntegral(IntegralConfig(limit=1.0, dt=1.0, band=0.1))
    assert banded.update(0.05, 1.0) == pytest.approx(0.05)
    assert banded.update(0.3, 1.0) == pytest.approx(0.05)  # held
    assert banded.update(-0.1, 1.0) == pytest.approx(0.05)  # at the band: held
    assert banded.update(-0.09, 1.0) == pytest.approx(-0.04)
    assert banded.update(math.nan, 1.0) == pytest.approx(-0.04)  # no error known: held, never NaN
    clipped = SpeedIntegral(IntegralConfig(limit=1.0, dt=1.0, clip=0.05))  # error saturation instead
    assert clipped.update(0.3, 1.0) == pytest.approx(0.05)  # a large error: at the clip's rate
    assert clipped.update(-0.02, 1.0) == pytest.approx(0.03)  # a small one: as it is
    assert clipped.update(-1.0, 1.0) == pytest.approx(-0.02)
    for name in ("band", "clip"):
        for bad in (0.0, -0.1, math.inf, math.nan):
            with pytest.raises(ValueError, match=name):
                IntegralConfig(limit=1.0, dt=1.0, **{name: bad})
    memory = MemoryConfig(IntegralConfig(limit=1.0, dt=0.02, gain=0.2, speed_range=(0.7, 1.5), band=0.1, clip=0.05))
    config = memory.integral
    assert (config.band, config.clip) == (0.1, 0.05) and MemoryConfig.from_dict(memory.to_dict()) == memory
    older = {k: v for k, v in memory.to_dict().items() if k not in ("band", "clip")}  # a checkpoint from before
    assert MemoryConfig.from_dict(older).integral == IntegralConfig(1.0, 0.02, 0.2, (0.7, 1.5))



def test_the_windup_decay_at_start_treats_the_walks_start_as_a_change_up():
    """WindupDecay.at_start: what I winds up over a walk's first (slow) steps decays toward its
    value at the start once the hip has passed v_d, as after a change up; with the feed-forward's
    start, toward I*(v_d). Without it, the same errors integrate as before."""
    from rabbit_policy.runtime.speed_integral import IntegralConfig, IntegralFeedforward, SpeedIntegral, WindupDecay

    errors = (0.5, 0.3, -0.2, 0.0, 0.2)  # slow first steps, then the hip passes v_d
    plain = SpeedIntegral(IntegralConfig(limit=10.0, dt=1.0, windup_decay=WindupDecay(seconds=4.0, tau=2.0)))
    assert [plain.update(e, 1.0) for e in errors] == pytest.approx([0.5, 0.8, 0.6, 0.6, 0.8])
    start = SpeedIntegral(IntegralConfig(limit=10.0, dt=1.0, windup_decay=WindupDecay(4.0, 2.0, at_start=True)))
    assert [start.update(e, 1.0) for e in errors] == pytest.approx([0.5, 0.8, 0.3, 0.15, 0.35])
    start.reset()  # every walk's start
    assert [start.update(e, 1.0) for e in errors] == pytest.approx([0.5, 0.8, 0.3, 0.15, 0.35])
    table = IntegralFeedforward((0.5, 1.5), (-0.2, -0.2), start=True)
    both = SpeedIntegral(IntegralConfig(limit=10.0, dt=1.0, windup_decay=WindupDecay(4.0, 2.0, True), feedforward=table))
    assert [both.update(e, 1.0) for e in errors] == pytest.approx([0.3, 0.6, -0.2 + 0.5 * 0.6, -0.2 + 0.25 * 0.6,
                                                                   -0.05 + 0.2])
    with pytest.raises(ValueError, match="at_start"):
        WindupDecay(at_start=1)


def test_the_windup_decay_drops_what_a_change_wound_up_once_the_hip_passes_the_new_command():
    """WindupDecay: after a change of v_d, I integrates as before until the error turns against
    the change; from then until ``seconds`` after the change it decays toward its value at the
    change (time constant ``tau``) while it integrates; at a constant command, and once the
    window is over, it integrates exactly as without the rule."""
    from rabbit_policy.runtime.memory import MemoryConfig
    from rabbit_policy.runtime.speed_integral import IntegralConfig, SpeedIntegral, WindupDecay

    decay = WindupDecay(seconds=4.0, tau=2.0)  # dt 1 s: a window of 4 decisions, half kept per decaying decision
    decaying = SpeedIntegral(IntegralConfig(limit=10.0, dt=1.0, windup_decay=decay))
    plain = SpeedIntegral(IntegralConfig(limit=10.0, dt=1.0))
    for error in (0.2, -0.1, 0.3):  # a constant command: no change, every error integrates
        assert decaying.update(error, 1.0) == plain.update(error, 1.0)
    assert decaying.value == pytest.approx(0.4)  # the value at the change below
    assert decaying.update(0.5, 1.4) == pytest.approx(0.9)  # a step up, the hip lagging: winds up as before
    assert decaying.update(0.3, 1.4) == pytest.approx(1.2)
    assert decaying.update(-0.2, 1.4) == pytest.approx(0.4 + 0.5 * (1.0 - 0.4))  # passed it: decays toward 0.4
    assert decaying.update(0.0, 1.4) == pytest.approx(0.4 + 0.25 * (1.0 - 0.4))  # the window's last decision
    assert decaying.update(0.2, 1.4) == pytest.approx(0.55 + 0.2)  # 4 decisions after the change: plain again
    assert decaying.update(-0.3, 1.0) == pytest.approx(0.45)  # a step down: a negative error is the lag
    assert decaying.update(0.1, 1.0) == pytest.approx(0.75 + 0.5 * (0.55 - 0.75))  # passed: toward 0.75
    decaying.reset()
    assert decaying.value == 0.0 and decaying.update(-0.5, 1.3) == pytest.approx(-0.5)  # no change seen yet
    for bad in ({"seconds": 0.0}, {"tau": -0.1}, {"seconds": math.inf}, {"tau": math.nan}, {"tau": "1"}):
        with pytest.raises(ValueError, match="windup decay"):
            WindupDecay(**bad)
    with pytest.raises(ValueError, match="windup decay tau must be at least dt"):
        IntegralConfig(limit=1.0, dt=1.0, windup_decay=WindupDecay(tau=0.5))
    with pytest.raises(ValueError, match="windup decay"):
        IntegralConfig(limit=1.0, dt=1.0, windup_decay={"seconds": 5.0})
    memory = MemoryConfig(IntegralConfig(limit=1.0, dt=0.02, gain=0.2, speed_range=(0.7, 1.5), windup_decay=WindupDecay()))
    recorded = memory.to_dict()  # as a checkpoint's info holds it: a plain dict
    assert recorded["windup_decay"] == {"seconds": 5.0, "tau": 1.0, "at_start": False}
    assert MemoryConfig.from_dict({**recorded, "windup_decay": {"seconds": 5.0, "tau": 1.0}}) == memory  # a checkpoint from before
    assert MemoryConfig.from_dict(recorded) == memory and memory.integral.windup_decay == WindupDecay()
    with pytest.raises(ValueError, match="windup decay"):
        MemoryConfig.from_dict({**recorded, "windup_decay": {"seconds": 5.0, "speed": 1.0}})
    older = {k: v for k, v in recorded.items() if k != "windup_decay"}  # a checkpoint from before the rule
    assert MemoryConfig.from_dict(older).integral.windup_decay is None


def test_the_integral_feedforward_shifts_by_the_steady_values_difference_at_a_change_and_may_start_there():
    """IntegralFeedforward: I* linear between the table's speeds, the end values beyond; a
    change from v to v' adds I*(v') - I*(v) (what the errors added stays) and, with ``start``,
    a walk's first decision starts I at I*(v_d), both within the range gate and the bound;
    every error still integrates, and without ``start`` a constant command integrates as
    without the table. A bad table is one line; a checkpoint records the table and one from
    before it loads without."""
    from dataclasses import replace

    from rabbit_policy.runtime.memory import MemoryConfig
    from rabbit_policy.runtime.speed_integral import IntegralConfig, IntegralFeedforward, SpeedIntegral, WindupDecay

    changes = IntegralFeedforward((0.8, 1.0, 1.2), (-0.2, 0.1, 0.3))
    table = replace(changes, start=True)
    assert [table.at(v) for v in (0.5, 0.8, 0.9, 1.1, 1.2, 2.0)] == pytest.approx([-0.2, -0.2, -0.05, 0.2, 0.3, 0.3])
    shifted, plain = (SpeedIntegral(IntegralConfig(limit=0.25, dt=1.0, feedforward=f)) for f in (changes, None))
    for error in (0.01, -0.02, 0.03):  # a constant command from the start: as without the table
        assert shifted.update(error, 0.9) == plain.update(error, 0.9)
    assert shifted.update(0.0, 1.0) == pytest.approx(0.02 + 0.15)  # the change adds I*(1.0) - I*(0.9)
    fed = SpeedIntegral(IntegralConfig(limit=0.25, dt=1.0, feedforward=table))
    assert fed.update(0.01, 0.9) == pytest.approx(-0.05 + 0.01)  # starts at I*(0.9), then integrates
    assert fed.update(0.02, 0.9) == pytest.approx(-0.02)
    assert fed.update(0.0, 1.1) == pytest.approx(-0.02 + 0.25)  # the change adds I*(1.1) - I*(0.9)
    assert fed.update(0.0, 1.2) == pytest.approx(0.25)  # + 0.1 would pass the bound: held at it
    fed.reset()
    assert fed.update(0.0, 1.2) == pytest.approx(0.25)  # a new walk: from the table again, bounded
    gated = SpeedIntegral(IntegralConfig(limit=1.0, dt=1.0, gain=1.0, speed_range=(0.8, 1.5), feedforward=table))
    assert gated.update(0.0, 0.9) == pytest.approx(-0.05)  # v_d + I = 0.85: inside the range
    assert gated.update(0.0, 0.85) == pytest.approx(-0.05)  # the shift -0.075 would leave it (0.725): gated at 0.8
    decay = WindupDecay(seconds=4.0, tau=2.0)  # the decay's anchor is the shifted value
    both = SpeedIntegral(IntegralConfig(limit=10.0, dt=1.0, windup_decay=decay, feedforward=changes))
    both.update(-0.2, 0.8)
    assert both.update(0.5, 1.0) == pytest.approx(-0.2 + 0.3 + 0.5)
    assert both.update(-0.2, 1.0) == pytest.approx(0.1 + 0.5 * (0.4 - 0.1))  # decays toward 0.1, not -0.2
    for speeds, values in (((1.0,), (0.1,)), ((1.0, 0.9), (0.0, 0.1)), ((0.8, math.nan), (0.0, 0.1)),
                           ((0.8, 1.0), (0.0, math.inf)), ((0.8, 1.0), (0.0,)), ((0.8, 1.0), ("a", 0.1))):
        with pytest.raises(ValueError, match="feed-forward"):
            IntegralFeedforward(speeds, values)
    with pytest.raises(ValueError, match="feed-forward start"):
        IntegralFeedforward((0.8, 1.0), (0.0, 0.1), start="yes")
    with pytest.raises(ValueError, match="feed-forward"):
        IntegralConfig(limit=1.0, dt=1.0, feedforward={"speeds": (0.8, 1.0), "values": (0.0, 0.1)})
    memory = MemoryConfig(IntegralConfig(limit=1.0, dt=0.02, gain=0.2, speed_range=(0.7, 1.5), feedforward=table))
    recorded = memory.to_dict()  # as a checkpoint's info holds it: a plain dict
    assert recorded["feedforward"] == {"speeds": (0.8, 1.0, 1.2), "values": (-0.2, 0.1, 0.3), "start": True}
    assert MemoryConfig.from_dict(recorded) == memory and memory.integral.feedforward == table
    assert MemoryConfig.from_dict({**recorded, "feedforward": {"speeds": [0.8, 1.0], "values": [0, 1]}}).integral.feedforward == (
        IntegralFeedforward((0.8, 1.0), (0.0, 1.0)))  # lists, as JSON would give them; no start: off
    with pytest.raises(ValueError, match="feedforward"):
        MemoryConfig.from_dict({**recorded, "feedforward": {"speeds": (0.8, 1.0)}})
    older = {k: v for k, v in recorded.items() if k != "feedforward"}  # a checkpoint from before the table
    assert MemoryConfig.from_dict(older).integral.feedforward is None


def test_learned_policy_checkpoint_round_trip(tmp_path):
    import torch

    from rabbit_hzd_controller.controller import ControllerConfig, validate_alpha
    from rabbit_policy.learning.env import RabbitHZDEnv
    from rabbit_policy.runtime.network import HZDPolicyNet, PolicyCheckpoint, parameter_count
    from rabbit_policy.runtime.speed_window import Observation

    bounds = RabbitHZDEnv().bounds
    torch.manual_seed(0)
    net = HZDPolicyNet(bounds.low, bounds.high)
    assert parameter_count(net) == 633  # 620 in the paper's count + Kd as the 21st output
    path = tmp_path / "policy.pt"
    PolicyCheckpoint(net.state_dict(), bounds.low, bounds.high, {"algo": "untrained"}).save(path)
    policy = make_policy("learned", policy_file=path)
    command = policy.act(Observation(1.2, 1.1, 0.1))
    validate_alpha(command.alpha, ControllerConfig())  # a gait the controller accepts
    assert bounds.low[-1] <= command.kd <= bounds.high[-1]
    (tmp_path / "broken.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(PolicyUnavailable, match="cannot load"):
        make_policy("learned", policy_file=tmp_path / "broken.pt")
    with pytest.raises(PolicyUnavailable, match="does not exist"):
        make_policy("learned", policy_file=tmp_path / "missing.pt")


def test_rate_limited_policy_moves_the_command_by_at_most_its_step():
    from rabbit_policy.runtime.policies import RateLimitedPolicy
    from rabbit_policy.runtime.speed_window import Observation

    seen = []

    class Recorder:
        name = "recorder"

        def act(self, observation):
            seen.append(observation)
            return None

    limited = RateLimitedPolicy(Recorder(), 0.1)
    limited.act(Observation(1.5, 1.5, 0.0))  # starts at the requested command
    limited.act(Observation(1.0, 1.5, -0.4))
    limited.act(Observation(1.0, 1.45, -0.45))
    assert [round(o.desired_speed, 9) for o in seen] == [1.5, 1.4, 1.3]
    # the error input is consistent with the limited command: mean(v_d - v) + (limited - requested)
    assert seen[1].mean_error == pytest.approx(-0.4 + 0.4) and seen[2].mean_error == pytest.approx(-0.45 + 0.3)
    assert limited.name == "recorder+limit0.1"
    with pytest.raises(ValueError):
        RateLimitedPolicy(Recorder(), 0.0)
    assert make_policy("classic", "", "nearest", max_command_step=0.2, decision=PER_STEP).name == \
        "classic/nearest+limit0.2"


def test_a_huge_command_logs_a_short_line():
    from rabbit_policy.runtime.commands import clamp_message

    line = clamp_message(1e308, 0.7, 1.5, 1.5, "/cmd_speed")
    assert "1e+308" in line and len(line) < 100


def test_a_schedule_outside_the_command_range_is_clamped_and_said_once_per_entry():
    from rabbit_policy.runtime.commands import clamp_schedule

    schedule, lines = clamp_schedule(((0.0, 0.3), (5.0, 1.0), (9.0, 2.0)))
    assert schedule == ((0.0, 0.7), (5.0, 1.0), (9.0, 1.5))
    assert lines == ["the command at t = 0 s, 0.3 m/s is outside [0.7, 1.5]; clamped to 0.70 m/s",
                     "the command at t = 9 s, 2 m/s is outside [0.7, 1.5]; clamped to 1.50 m/s"]
    with pytest.raises(ValueError, match="finite"):
        clamp_schedule(((0.0, float("nan")),))


def test_calibrated_interpolation_picks_the_blend_measured_to_walk_at_the_command():
    from rabbit_policy.runtime.gait_library import Calibration

    library = GaitLibrary.load()
    assert library.calibration is not None  # shipped: interpolation.json beside the gaits
    bare = GaitLibrary(library.gaits)
    # a made-up calibration for three gaits: the first pair's middle blends fail, the
    # second pair walks faster than its design speeds in the middle
    three = GaitLibrary(library.gaits[:3])
    lo, mid, hi = three.speeds
    calibration = Calibration((((0.0, lo), (0.5, None), (1.0, mid)),
                               ((0.0, mid), (0.5, hi + 0.2), (1.0, hi))))
    calibrated = GaitLibrary(three.gaits, calibration)
    # between the first two gaits only the failed middle would bracket: the nearest gait instead
    between = 0.5 * (lo + mid)
    assert calibrated.interpolate(between).alpha == three.nearest(between).alpha
    # a speed the second pair's blends walk at: the blend by measured speed, not by design speed
    target = hi + 0.1
    chosen = calibrated.interpolate(min(target, hi))  # hi itself: its own gait (clamped)
    assert chosen.alpha == three.gaits[-1].alpha
    w = calibration.weight_for(1, mid + 0.5 * (hi - mid))
    assert w is not None and 0.0 < w < 0.5 + 1e-9
    assert bare.interpolate(1.05).info["weight"] == pytest.approx((1.05 - 1.0) / 0.1)
    with pytest.raises(ValueError, match="covers"):
        GaitLibrary(library.gaits[:2], calibration)


@pytest.mark.parametrize("content", ["{}", "[1, 2]", "not json", '{"speed": "fast"}'])
def test_a_gait_directory_holding_no_gait_is_one_line_and_exit_2(tmp_path, content):
    """``--gait-dir`` with a file that is not a gait: one line naming it, exit status 2
    (bad input), never a traceback or 1 (1 means fell or stalled)."""
    import subprocess
    import sys
    from pathlib import Path

    (tmp_path / "gait_1.00.json").write_text(content)
    script = Path(__file__).resolve().parents[2] / "scripts" / "walk.py"
    out = subprocess.run([sys.executable, str(script), "--gait-dir", str(tmp_path), "--duration", "0.1"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert "Traceback" not in out.stderr and "gait_1.00.json" in lines[-1] and "not a gait file" in lines[-1]


def test_a_file_for_the_other_controller_is_refused_not_ignored():
    """--policy-file with classic, or a gait directory with learned, would be silently
    unused: each is a one-line error instead (every entry point builds policies here)."""
    with pytest.raises(ValueError, match="for the learned controller"):
        make_policy("classic", policy_file="runs/es0/best.pt")
    with pytest.raises(ValueError, match="the learned one takes a policy file"):
        make_policy("learned", gait_dir="my_gaits")


def test_decision_clock_once_per_step_and_every_n_ticks():
    """The rule policy_node and ClosedLoop share (stamps: sim time in ticks here)."""
    from rabbit_policy.runtime.decision_clock import DecisionClock

    clock = DecisionClock(0, window=1000)
    assert clock.sample(0, 5.0, 1.0) == []  # the placed state is no sample
    for stamp in range(1, 11):
        assert clock.sample(stamp, 1.0 if stamp <= 5 else 2.0, 1.5) == []
        assert clock.sample(stamp, 9.0, 1.5) == []  # a state sent again (lockstep re-send) is one sample
    assert clock.switch(4, 1.5)[0].mean_speed == pytest.approx(1.0)  # samples 1..5: the state after the switch
    assert clock.switch(12, 1.5) == []  # its next sample (13) is not in yet
    (due,) = clock.sample(13, 2.0, 1.5)
    assert due.mean_speed == 2.0 and due.mean_error == pytest.approx(-0.5)  # samples 6..13
    periodic = DecisionClock(5, window=1000)
    decided = [stamp for stamp in range(1, 31) for _ in periodic.sample(stamp, 1.0, 1.0)]
    assert decided == [5, 10, 15, 20, 25, 30]  # multiples of the period since the placement
    periodic.switch(30, 1.0)
    periodic.switch(40, 1.0)
    for stamp in range(31, 45):
        due = periodic.sample(stamp, float(stamp), 1.0)
    assert due == [] and periodic.sample(45, 45.0, 1.0)[0].mean_speed == pytest.approx(sum(range(36, 46)) / 10)
    assert periodic.sample(3, 1.0, 1.0) == [] and periodic.window.newest_stamp == 3  # a reset: afresh


def test_a_speed_schedule_applies_each_change_at_the_first_state_at_or_after_its_time():
    """One rule for ClosedLoop and policy_node (stamps in ns, 1 ns of slack for decimal
    seconds; several changes due at once: the last), started over after a reset."""
    from rabbit_policy.runtime.speed_schedule import SpeedSchedule

    schedule = SpeedSchedule(((1.0, 1.2), (6.132268422788288, 1.416), (6.2, 0.8)))
    assert schedule.due(999_000_000) is None
    assert schedule.due(999_999_999) == 1.2  # 1 ns short of 1 s: the float sum of 1000 ms steps
    assert schedule.due(1_000_000_000) is None  # applied once
    assert schedule.next_stamp == 6_132_268_423
    assert schedule.due(6_132_000_000) is None and schedule.due(6_133_000_000) == 1.416  # the first state after
    assert schedule.due(7_000_000_000) == 0.8 and schedule.next_stamp is None
    schedule.restart()
    assert schedule.due(10_000_000_000) == 0.8  # all at once: the last


def test_policy_node_takes_a_speed_schedule_checked_as_walk_pys():
    from rabbit_policy.policy_driver import speed_schedule

    assert speed_schedule("", 1.0) is None
    assert speed_schedule("2:1.2,4.5:0.9", 1.0).changes == ((2_000_000_000, 1.2), (4_500_000_000, 0.9))
    for text, message in (("0:1.2", "times must increase"), ("2:1.2,2.05:1.0", "at least 0.1 s apart"),
                          ("2-1.2", "time:speed")):
        with pytest.raises(ValueError, match=message):
            speed_schedule(text, 1.0)


@pytest.mark.parametrize("output, inputs", [("sigmoid", 3), ("clip", 25), ("tanh", 30)])
def test_the_numpy_forward_pass_is_torchs_within_float32_rounding(output, inputs):
    """Issue 38 item 2: the network decides without torch; every output within 1e-6 of its
    range of torch's, on random weights (large enough to reach the clip and saturations)."""
    import torch

    from rabbit_policy.runtime.network import HZDPolicyNet, NetworkForward

    rng = np.random.default_rng(inputs)
    low = rng.uniform(-1.5, 0.0, 21)
    high = low + rng.uniform(0.1, 150.0, 21)
    torch.manual_seed(inputs)
    net = HZDPolicyNet(low, high, output=output, inputs=inputs)
    with torch.no_grad():
        for p in net.parameters():
            p.mul_(3.0)
    forward = NetworkForward.of(net)
    x = (rng.normal(size=(500, inputs)) * net.scale.numpy() * 2 + net.offset.numpy()).astype(np.float32)
    with torch.no_grad():
        expected = net(torch.as_tensor(x)).numpy().astype(float)
    got = np.array([forward(row) for row in x])
    assert np.max(np.abs(got - expected) / (high - low)) < 1e-6
    with torch.no_grad():
        for p in net.parameters():
            p.zero_()
    assert np.array_equal(forward(x[0]), got[0])  # a snapshot: the network's later weights do not reach it


def test_quiet_samples_added_at_once_are_the_samples_added_one_by_one():
    """DecisionClock.add_quiet (the compiled loop's samples between two decisions) against
    sample() on each: the same observations after, and a run that would hold a decision is
    refused."""
    from rabbit_policy.runtime.decision_clock import DecisionClock

    rng = np.random.default_rng(3)
    speeds = (1.0 + 0.1 * rng.standard_normal(300)).tolist()
    for period in (0, 20):
        one, many = DecisionClock(period, 100), DecisionClock(period, 100)
        decided = []
        for i, v in enumerate(speeds[:45], start=1):
            decided += one.sample(i, v, 1.1)
        many.add_quiet(range(1, 20), speeds[:19], 1.1)
        decided_many = many.sample(20, speeds[19], 1.1)
        many.add_quiet(range(21, 40), speeds[20:39], 1.1)
        decided_many += many.sample(40, speeds[39], 1.1)
        many.add_quiet(range(41, 46), speeds[40:45], 1.1)
        assert decided == decided_many
        assert one.observe(1.1) == many.observe(1.1)
        if period:
            with pytest.raises(ValueError, match="not quiet"):
                many.add_quiet(range(46, 70), speeds[45:69], 1.1)  # 60 is due


def test_a_policy_copy_shares_what_no_decision_changes_and_copies_its_memory():
    """``copy_policy`` (the return map's and the ceiling's copies, a few per map evaluation)
    shares the network, its forward pass and the gait libraries, and copies the memory: the
    copy decides as the original would, and its decisions leave the original's memory as
    it was."""
    from rabbit_policy.runtime.policies import copy_policy
    from rabbit_policy.runtime.speed_window import Observation

    policy = make_policy("learned")
    copied = copy_policy(policy)
    assert copied.net is policy.net and copied.forward is policy.forward
    assert copied.residual.library is policy.residual.library
    assert copied.memory is not policy.memory
    body = (0.0, 0.0, 0.3, 2.0, 0.9)  # the shipped policy's recovery rule reads the body state
    observation = Observation(1.0, 0.9, 0.1, body)
    assert copied.act(observation) == policy.act(observation)  # the same decision from the same memory
    before = copy_policy(policy)
    copied.act(Observation(1.0, 0.5, 0.5, body))
    assert before.act(observation) == policy.act(observation)  # the copy's decisions left the original alone
    recovery = make_policy("recovery")
    assert copy_policy(recovery).classic.library is recovery.classic.library
