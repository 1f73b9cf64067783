"""The HZD controller core: the control law, gain/alpha semantics and input validation."""

import math

import numpy as np
import pytest

from rabbit_hzd_controller.alpha import alpha_matrix, expand_alpha
from rabbit_hzd_controller.bezier import bezier, bezier_derivative
from rabbit_hzd_controller.controller import ControllerConfig, HZDController, Leg
from rabbit_hzd_controller.kinematics import LegGeometry, foot_from_hip, foot_velocity_from_hip
from rabbit_hzd_controller.phase import PhaseBounds, phase_bounds_from_alpha, stance_hip_position
from rabbit_policy.runtime.gait_library import GaitLibrary

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def gait():
    return GaitLibrary.load().nearest(1.0)


# ---- the control law written out from the paper: the reference the controller's inlined
# ---- 1 kHz tick is checked against (the package has one implementation, the tick)
def phase(p_hip: float, bounds: PhaseBounds) -> float:
    """tau = (p_hip - p_plus) / (p_minus - p_plus), saturated to [0, 1]."""
    return min(1.0, max(0.0, (p_hip - bounds.p_plus) / bounds.span))


def phase_rate(p_hip: float, p_hip_rate: float, bounds: PhaseBounds) -> float:
    """d tau / dt by the chain rule; zero where tau is saturated."""
    return p_hip_rate / bounds.span if 0.0 < (p_hip - bounds.p_plus) / bounds.span < 1.0 else 0.0


def pd_torque(q_d: float, dq_d: float, q: float, dq: float, kp: float, kd: float, limit: float) -> float:
    """u = Kp (q_d - q) + Kd (dq_d - dq), saturated to +-limit (N m)."""
    return min(limit, max(-limit, kp * (q_d - q) + kd * (dq_d - dq)))


def reference_torques(alpha, kp, kd, limit, stance, q, dq):
    """The control law written out from the paper."""
    geom = LegGeometry()
    m = alpha_matrix(alpha)
    idx = (3, 4, 5, 6) if stance == Leg.LEFT else (5, 6, 3, 4)
    y = [q[i] for i in idx]
    dy = [dq[i] for i in idx]
    bounds = phase_bounds_from_alpha(alpha, geom)
    p = stance_hip_position(geom, q[2], y[0], y[1])
    dp = -foot_velocity_from_hip(geom, q[2], y[0], y[1], dq[2], dy[0], dy[1])[0]
    tau, dtau = phase(p, bounds), phase_rate(p, dp, bounds)
    u = [pd_torque(bezier(m[:, j], tau), bezier_derivative(m[:, j], tau) * dtau, y[j], dy[j], kp, kd, limit)
         for j in range(4)]
    return u if stance == Leg.LEFT else [u[2], u[3], u[0], u[1]]


@pytest.mark.parametrize("stance", [Leg.LEFT, Leg.RIGHT])
def test_compute_matches_the_written_out_law(gait, stance):
    rng = np.random.default_rng(7)
    cfg = ControllerConfig(kp=gait.kp)
    for _ in range(200):
        c = HZDController(gait.alpha, gait.kd, cfg, stance=stance)
        q = [0.0, 0.9, *rng.uniform([-0.2, -0.5, 0.1, -0.5, 0.1], [0.2, 0.6, 1.0, 0.6, 1.0])]  # hip high: no touchdown
        dq = list(rng.normal(size=7))
        got = c.compute(q, dq)
        want = reference_torques(gait.alpha, gait.kp, gait.kd, 150.0, stance, q, dq)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)
        assert c.stance == stance  # swing foot far above ground: no switch


@pytest.mark.parametrize("stance", [Leg.LEFT, Leg.RIGHT])
def test_the_reference_is_what_the_pd_law_tracked(gait, stance):
    """``reference()`` (the /hzd/reference topic's source, off the hot path): the desired
    outputs and rates of the last tick, per leg; unsaturated torques are Kp (y_d - y) + Kd
    (dy_d - dy) of them, also while a within-step blend is running."""
    rng = np.random.default_rng(3)
    cfg = ControllerConfig(kp=gait.kp, torque_limit=1e9)
    other = GaitLibrary.load().nearest(1.3)
    for k in range(100):
        c = HZDController(gait.alpha, gait.kd, cfg, stance=stance)
        q = [0.0, 0.9, *rng.uniform([-0.2, -0.5, 0.1, -0.5, 0.1], [0.2, 0.6, 1.0, 0.6, 1.0])]
        dq = list(rng.normal(size=7))
        if k % 2:  # a gait applied within the step, blended in from the outputs in force
            c.compute(q, dq)
            c.apply_now(other.alpha, other.kd)
        torques = c.compute(q, dq)
        yd, dyd = c.reference()
        y, dy = q[3:7], dq[3:7]
        want = [c.config.kp * (a - b) + c.kd * (da - db) for a, b, da, db in zip(yd, y, dyd, dy)]
        np.testing.assert_allclose(torques, want, rtol=1e-9, atol=1e-6)


def test_saturated_phase_has_no_rate_and_the_pd_law_saturates(gait):
    """The controller holds tau in [0, 1] with a zero rate outside the step, and clips
    u = Kp e + Kd de at the torque limit."""
    c = HZDController(gait.alpha, gait.kd, ControllerConfig(kp=gait.kp))
    q = [0.0, 0.9, 0.0, 1.2, 0.2, 0.4, 0.2]  # stance foot far ahead of the hip: before the step, tau = 0
    c.compute(q, [0.0] * 7)
    assert c.tau == 0.0
    q_far = [0.0, 0.9, 0.0, -0.9, 0.2, 0.4, 0.2]  # stance foot far behind: past the step, tau = 1
    torques = c.compute(q_far, [0.0] * 7)
    assert c.tau == 1.0
    assert max(abs(t) for t in torques) == pytest.approx(150.0)


def test_torques_never_exceed_the_limit(gait):
    rng = np.random.default_rng(8)
    c = HZDController(gait.alpha, gait.kd)
    for _ in range(200):
        q = [0.0, 0.9, *rng.uniform(-1.5, 1.5, size=5)]
        u = c.compute(q, list(rng.normal(scale=20, size=7)))
        assert max(abs(v) for v in u) <= 150.0


def _touchdown_state(gait):
    """A state at the end of a step: phase past 1/2, swing foot below the ground."""
    geom = LegGeometry()
    end = alpha_matrix(gait.alpha)[-1]
    pitch = gait.touchdown_pitch()
    fx, fz = foot_from_hip(geom, pitch, end[0], end[1])
    q = [0.0, -fz - 1e-4, pitch, end[0], end[1], end[2], end[3]]
    return q, [0.0] * 7


def test_new_kd_applies_at_once_new_alpha_at_touchdown(gait):
    c = HZDController(gait.alpha, gait.kd)
    other = expand_alpha(gait.free + 0.01)
    c.set_alpha(other)
    c.set_kd(gait.kd + 10.0)
    assert c.kd == gait.kd + 10.0
    assert c.alpha == gait.alpha  # not yet
    assert c.pending_alpha == tuple(other)
    q_mid = [0.0, 0.9, 0.0, 0.3, 0.5, 0.1, 0.5]
    c.compute(q_mid, [0.0] * 7)
    assert c.alpha == gait.alpha and c.steps == 0
    q, dq = _touchdown_state(gait)
    c.compute(q, dq)
    assert c.touchdown and c.steps == 1 and c.stance == Leg.RIGHT
    assert c.alpha == tuple(other) and c.pending_alpha is None


def test_one_switch_however_long_the_foot_stays_down(gait):
    c = HZDController(gait.alpha, gait.kd)
    q, dq = _touchdown_state(gait)
    for _ in range(50):  # the same touchdown state, tick after tick (contact chatter)
        c.compute(q, dq)
    assert c.steps == 1


@pytest.mark.parametrize(
    "bad",
    [
        [0.0] * 23,
        [float("nan")] * 24,
        [float("inf")] + [0.0] * 23,
        list(range(24)),  # violates the impact equalities
    ],
)
def test_bad_alpha_is_rejected_and_the_last_good_kept(gait, bad):
    c = HZDController(gait.alpha, gait.kd)
    with pytest.raises(ValueError):
        c.set_alpha(bad)
    assert c.alpha == gait.alpha and c.pending_alpha is None


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -1.0])
def test_bad_kd_is_rejected(gait, bad):
    c = HZDController(gait.alpha, gait.kd)
    with pytest.raises(ValueError):
        c.set_kd(bad)
    assert c.kd == gait.kd


def test_degenerate_step_is_rejected(gait):
    standing = expand_alpha(np.tile([0.0, 0.0, 0.0, 0.0], 5))  # both legs straight together
    with pytest.raises(ValueError):
        HZDController(standing, 10.0)


def test_config_validation():
    with pytest.raises(ValueError):
        ControllerConfig(kp=-1.0)
    with pytest.raises(ValueError):
        ControllerConfig(touchdown_min_phase=1.5)
    assert math.isfinite(ControllerConfig().kp)


def test_blend_makes_the_desired_outputs_continuous_across_a_gait_change():
    from rabbit_hzd_controller.gait_state import state_on_gait

    library = GaitLibrary.load()
    fast, slow = library.nearest(1.5), library.nearest(1.4)
    q, _ = state_on_gait(fast.alpha, 1.5, tau=1.0)  # end of a step: the swing foot is on the ground
    q[1] -= 1e-6  # ... and a hair into it
    still = [0.0] * 7  # no motion: the torques are Kp (y_d - y) alone

    def torques(blend: float, new_alpha) -> list[float]:
        c = HZDController(fast.alpha, fast.kd, ControllerConfig(kp=fast.kp, blend_phase=blend))
        c.set_alpha(new_alpha)
        out = c.compute(q, still)
        assert c.touchdown and c.alpha == tuple(new_alpha)
        return out

    kept = torques(0.0, fast.alpha)  # the old gait goes on
    jumped = torques(0.0, slow.alpha)  # the new gait at once: the outputs jump
    blended = torques(0.3, slow.alpha)  # the new gait, starting where the old one was
    np.testing.assert_allclose(blended, kept, atol=1e-6)
    assert max(abs(a - b) for a, b in zip(jumped, kept)) > 50.0
    with pytest.raises(ValueError):
        ControllerConfig(blend_phase=1.5)


def test_blend_fades_out_within_its_phase(gait):
    """A gait queued for the touchdown (``set_alpha``) with ``blend_phase`` 0.2: right after
    the touchdown the outputs start where the old gait's were and fade into the new gait's
    by a smoothstep over 0.2 of phase; past it the plain law of the new gait, and the blend
    is over for good. Checked through torques on states at rest on the new gait (where the
    plain law gives only Kp terms: kp * offset * w), kp low so that nothing saturates."""
    from rabbit_hzd_controller.gait_state import state_on_gait

    new = GaitLibrary.load().nearest(1.2)
    config = ControllerConfig(kp=300.0, blend_phase=0.2)
    c = HZDController(gait.alpha, gait.kd, config)
    c.set_alpha(new.alpha)
    q_end, _ = state_on_gait(gait.alpha, gait.speed, tau=1.0)  # the swing foot lands
    c.compute(q_end, [0.0] * 7)
    assert c.touchdown and c.stance is Leg.RIGHT and c.alpha == tuple(new.alpha)
    start = c.tau  # where the blend starts (the new gait's phase at the touchdown state)
    plain = HZDController(new.alpha, new.kd, config, stance=Leg.RIGHT)

    def offset(tau: float) -> np.ndarray:
        q, _ = state_on_gait(new.alpha, new.speed, tau=tau, stance=Leg.RIGHT)
        return np.array(c.compute(q, [0.0] * 7)) - np.array(plain.compute(q, [0.0] * 7))

    def w(tau: float) -> float:  # smoothstep down over the blend
        r = (tau - start) / 0.2
        return 1.0 - r * r * (3.0 - 2.0 * r)

    first = offset(start + 0.02)
    assert np.max(np.abs(first)) > 1.0  # N m: the outputs start at the old gait's
    for tau in (0.08, 0.15):
        np.testing.assert_allclose(offset(tau), first * w(tau) / w(start + 0.02), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(offset(0.6), 0.0, atol=1e-9)  # past it: the plain law
    np.testing.assert_allclose(offset(0.1), 0.0, atol=1e-9)  # and the blend does not come back


def _desired(c: HZDController, q, dq, eps: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """The desired outputs y_d and dy_d/dt (stance/swing order) the controller tracks at
    (q, dq), read back from copies of it without saturation: with Kd = 0 the torques are
    Kp (y_d - y); with Kd = 1 they grow by dy_d - dy."""
    import copy

    out = []
    for kd in (0.0, 1.0):
        probe = copy.deepcopy(c)
        probe.kd = kd
        probe.config = ControllerConfig(kp=probe.config.kp, torque_limit=1e9,
                                        within_step_blend=probe.config.within_step_blend)
        out.append(np.array(probe.compute(q, dq)))
    kp = c.config.kp
    stance = c.stance
    y = np.array([q[3], q[4], q[5], q[6]] if stance == 0 else [q[5], q[6], q[3], q[4]])
    dy = np.array([dq[3], dq[4], dq[5], dq[6]] if stance == 0 else [dq[5], dq[6], dq[3], dq[4]])
    order = [0, 1, 2, 3] if stance == 0 else [2, 3, 0, 1]
    u0, u1 = out[0][order], out[1][order]
    return u0 / kp + y, (u1 - u0) + dy


def test_apply_now_keeps_the_desired_outputs_and_their_rates_continuous():
    from rabbit_hzd_controller.gait_state import state_on_gait

    library = GaitLibrary.load()
    first, second, third = library.nearest(1.0), library.nearest(0.7), library.nearest(1.5)
    q, dq = state_on_gait(first.alpha, 1.0, tau=0.3)
    c = HZDController(first.alpha, 0.0, ControllerConfig(within_step_blend=0.2))
    c.compute(q, dq)
    before = _desired(c, q, dq)
    c.apply_now(second.alpha, 10.0)
    assert c.alpha == second.alpha and c.kd == 10.0
    after = _desired(c, q, dq)
    np.testing.assert_allclose(after[0], before[0], atol=1e-9)  # y_d continuous
    np.testing.assert_allclose(after[1], before[1], atol=1e-6)  # dy_d/dt continuous
    c.compute(q, dq)  # the blend starts at this state
    # a second change in the middle of the blend starts from the blended outputs
    q2, dq2 = state_on_gait(first.alpha, 1.0, tau=0.35)
    mid = _desired(c, q2, dq2)
    c.compute(q2, dq2)
    c.apply_now(third.alpha)
    np.testing.assert_allclose(_desired(c, q2, dq2)[0], mid[0], atol=1e-9)
    np.testing.assert_allclose(_desired(c, q2, dq2)[1], mid[1], atol=1e-6)
    # after the blend's phase the new gait's own outputs are tracked
    plain = HZDController(third.alpha, 0.0)
    q3, dq3 = state_on_gait(first.alpha, 1.0, tau=0.9)
    c.compute(q2, dq2)
    np.testing.assert_allclose(_desired(c, q3, dq3)[0], _desired(plain, q3, dq3)[0], atol=1e-9)


def test_apply_now_rejects_bad_input_and_changes_nothing(gait):
    c = HZDController(gait.alpha, gait.kd)
    with pytest.raises(ValueError):
        c.apply_now([float("nan")] * 24)
    with pytest.raises(ValueError):
        c.apply_now(gait.alpha, -1.0)
    assert c.alpha == tuple(gait.alpha) and c.kd == gait.kd
    with pytest.raises(ValueError):
        ControllerConfig(within_step_blend=-0.1)
    with pytest.raises(ValueError):
        ControllerConfig(min_phase_rate=float("nan"))


def test_apply_now_at_once_tracks_the_new_gait_from_the_next_tick():
    """within_step_blend 0: no blend, no queue — the paper's alpha applied as it comes."""
    from rabbit_hzd_controller.gait_state import state_on_gait

    library = GaitLibrary.load()
    first, second = library.nearest(1.0), library.nearest(0.7)
    config = ControllerConfig(within_step_blend=0.0, within_step_until=1.0)
    q, dq = state_on_gait(first.alpha, 1.0, tau=0.8)
    c = HZDController(first.alpha, 10.0, config)
    c.compute(q, dq)
    c.apply_now(second.alpha, 10.0)
    assert c.alpha == second.alpha and c.pending_alpha is None  # not queued at 0.8 of phase
    plain = HZDController(second.alpha, 10.0, config)
    plain.tau = c.tau
    assert c.compute(q, dq) == plain.compute(q, dq)
    blended = HZDController(first.alpha, 10.0)
    blended.compute(q, dq)
    blended.apply_now(second.alpha, 10.0)
    assert blended.pending_alpha == second.alpha  # today's rule: queued from 0.6 of phase


def test_min_phase_rate_moves_the_phase_in_time_while_the_hip_stalls(gait):
    from rabbit_hzd_controller.gait_state import state_on_gait

    q, dq = state_on_gait(gait.alpha, 1.0, tau=0.15)
    dq = list(dq)
    dq[0] = 0.0
    stalled = HZDController(gait.alpha, gait.kd)
    moving = HZDController(gait.alpha, gait.kd, ControllerConfig(min_phase_rate=2.0))
    for _ in range(100):  # the same state every tick: the hip does not move
        stalled.compute(q, dq)
        moving.compute(q, dq)
    assert stalled.tau == pytest.approx(0.15, abs=1e-6)
    assert moving.tau == pytest.approx(0.15 + 99 * 0.002, abs=1e-9)  # 99 ticks of 1 ms at 2 / s after the first
    assert moving.tau_rate == 2.0
    assert moving.steps == 0  # the touchdown rule reads the hip: no step counted
