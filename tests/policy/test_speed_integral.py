"""The speed integral on the gait command (rabbit_policy.runtime.speed_integral): what it accumulates
within its bound, where it holds (the library's range, a band), the windup decay at a change and
at the start, and the integral feedforward."""

from __future__ import annotations

import math

import pytest

from rabbit_msgs_py.decision_ticks import PER_STEP

from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.spec.make import make_policy

pytestmark = pytest.mark.unit


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
    assert recorded["windup_decay"] == {"seconds": 5.0, "tau": 1.0, "at_start": False, "disturbance": None}
    assert MemoryConfig.from_dict({**recorded, "windup_decay": {"seconds": 5.0, "tau": 1.0}}) == memory  # a checkpoint from before
    assert MemoryConfig.from_dict(recorded) == memory and memory.integral.windup_decay == WindupDecay()
    with pytest.raises(ValueError, match="windup decay"):
        MemoryConfig.from_dict({**recorded, "windup_decay": {"seconds": 5.0, "speed": 1.0}})
    older = {k: v for k, v in recorded.items() if k != "windup_decay"}  # a checkpoint from before the rule
    assert MemoryConfig.from_dict(older).integral.windup_decay is None


def test_a_disturbance_opens_the_windup_decay_as_a_change_its_way_does():
    """WindupDecay.disturbance: at a constant command, an error beyond it (a push slowed the
    hip) opens the decay's window anchored at I then; once the hip passes the command, what I
    wound up meanwhile decays toward that anchor. Inside an open window the anchor is kept and
    the window starts again. Errors within it, and no disturbance set, integrate as before."""
    from rabbit_policy.runtime.speed_integral import IntegralConfig, SpeedIntegral, WindupDecay

    def integral(disturbance):
        return SpeedIntegral(IntegralConfig(limit=10.0, dt=1.0, windup_decay=WindupDecay(4.0, 2.0, False, disturbance)))

    plain, pushed = integral(None), integral(0.25)
    steady = (0.1, -0.2, 0.25, -0.25, 0.0)  # within the disturbance: the same arithmetic as without the rule
    assert [pushed.update(e, 1.0) for e in steady] == [plain.update(e, 1.0) for e in steady]
    anchor = pushed.value
    assert anchor == pytest.approx(-0.1)
    assert pushed.update(0.4, 1.0) == pytest.approx(0.3)  # pushed back: winds up as before ...
    assert pushed.update(0.3, 1.0) == pytest.approx(0.6)  # ... and again (the window starts again, same anchor)
    assert pushed.update(-0.1, 1.0) == pytest.approx(anchor + 0.5 * (0.5 - anchor))  # passed: toward the anchor
    assert pushed.update(0.0, 1.0) == pytest.approx(anchor + 0.25 * (0.5 - anchor))
    assert [plain.update(e, 1.0) for e in (0.4, 0.3, -0.1, 0.0)] == pytest.approx([0.3, 0.6, 0.5, 0.5])  # kept
    for _ in range(4):  # the window closes: plain integration again
        pushed.update(0.0, 1.0)
    value = pushed.value
    assert pushed.update(0.1, 1.0) == pytest.approx(value + 0.1)
    fast = integral(0.25)  # pushed forward: a negative error opens it the other way
    assert fast.update(-0.5, 1.0) == -0.5  # a walk's first decision is no disturbance: no window
    assert fast.update(0.2, 1.0) == pytest.approx(-0.3)
    assert fast.update(-0.5, 1.0) == pytest.approx(-0.8)  # now it is: anchored at -0.3
    assert fast.update(0.2, 1.0) == pytest.approx(-0.3 + 0.5 * (-0.6 + 0.3))  # passed: toward -0.3
    for bad in (0.0, -0.1, math.nan, True, "0.2"):
        with pytest.raises(ValueError, match="windup decay disturbance"):
            WindupDecay(disturbance=bad)


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

