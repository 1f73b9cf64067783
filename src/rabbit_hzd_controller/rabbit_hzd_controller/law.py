"""The HZD law, compiled: one control tick on plain arrays (numba ``@njit``).

The one implementation of the per-tick law (phase, Bezier outputs, blending, the impact switch,
the PD law and its saturation). :class:`~.controller.HZDController` keeps its state in the
arrays below and calls :func:`control` every tick (the controller node does, through it), and
the ROS-free loop calls the same function inside its compiled inner loop
(:mod:`rabbit_policy.experiment.ticks`), between ``mj_step`` calls. Compiled once per machine and
cached (``cache=True``: next to this file, or in numba's user-wide cache when the install is
read-only).

Arrays (float64):

* ``cfg`` (:data:`CONFIG_SIZE`): the constant settings, indices ``KP`` ... ``TICK`` (N m/rad, N m,
  m, m, 1, m, 1, 1, 1/s, s).
* ``state`` (:data:`STATE_SIZE`): the stance leg (0 left, 1 right), steps, phase tau and its
  rate (1/s), the touchdown flag of the last tick, Kd (N m s/rad), the queued Kd (NaN: none),
  flags for a queued gait, a replaced gait, a blend and the replaced gait's blend, the next
  blend's length, then the blend in force and the replaced gait's blend (each: start phase, 4
  position offsets rad, 4 rate offsets rad per unit phase, length).
* ``gaits`` (3 x :data:`SLOT_SIZE`): the active, queued and replaced gaits, each the 4 outputs'
  6 coefficients (rad; output-major: stance hip, stance knee, swing hip, swing knee), then
  p_plus, p_minus and the span (m).

Every expression is written in the order of the Python law it replaced, so the torques are the
same floats (walks compared bit for bit with that law through a worktree, docs/benchmarks.md;
``tests/hzd_controller`` checks it against the law written out from the paper).
"""

from __future__ import annotations

from math import atan2, cos, hypot, pi, sin

import numpy as np
from numba import njit

from .kinematics import foot_position

# cfg
KP, TORQUE_LIMIT, FEMUR, TIBIA, TOUCHDOWN_MIN_PHASE, TOUCHDOWN_HEIGHT, BLEND_PHASE, WITHIN_STEP_BLEND, \
    MIN_PHASE_RATE, TICK = range(10)
CONFIG_SIZE = 10

# state
STANCE, STEPS, TAU, TAU_RATE, TOUCHDOWN, KD, PENDING_KD, HAS_PENDING, HAS_REPLACED, HAS_BLEND, \
    HAS_REPLACED_BLEND, NEXT_BLEND_LENGTH = range(12)
BLEND = 12
"""The blend in force: start phase, 4 offsets, 4 rates, length (10 entries)."""
REPLACED_BLEND = 22
"""The replaced gait's blend, in the same layout."""
BLEND_SIZE = 10
STATE_SIZE = 32
# within a blend record (from BLEND or REPLACED_BLEND): its start phase, the 4 position offsets
# (rad), the 4 rate offsets (rad per unit phase), its length (phase)
B_START, B_OFFSET, B_RATE, B_LENGTH = 0, 1, 5, 9

# gait slots
ACTIVE, PENDING, REPLACED = range(3)
COEFFS = 24
P_PLUS, P_MINUS, SPAN = 24, 25, 26
SLOT_SIZE = 27

_COMB5 = (1.0, 5.0, 10.0, 10.0, 5.0, 1.0)
_COMB4 = (1.0, 4.0, 6.0, 4.0, 1.0)


@njit(cache=True)
def bezier5(g: np.ndarray, slot: int, j: int, t: float) -> float:
    """Output ``j``'s degree-5 Bezier of gait ``slot`` at ``t`` (``bezier.bezier``'s arithmetic)."""
    s = 1.0 - t
    tp0, tp1 = 1.0, t
    tp2 = tp1 * t
    tp3 = tp2 * t
    tp4 = tp3 * t
    tp5 = tp4 * t
    sp1 = s
    sp2 = sp1 * s
    sp3 = sp2 * s
    sp4 = sp3 * s
    sp5 = sp4 * s
    base = 6 * j
    acc = 0.0
    acc += g[slot, base] * (_COMB5[0] * tp0 * sp5)
    acc += g[slot, base + 1] * (_COMB5[1] * tp1 * sp4)
    acc += g[slot, base + 2] * (_COMB5[2] * tp2 * sp3)
    acc += g[slot, base + 3] * (_COMB5[3] * tp3 * sp2)
    acc += g[slot, base + 4] * (_COMB5[4] * tp4 * sp1)
    acc += g[slot, base + 5] * (_COMB5[5] * tp5 * 1.0)
    return acc


@njit(cache=True)
def bezier5_derivative(g: np.ndarray, slot: int, j: int, t: float) -> float:
    """d/dtau of :func:`bezier5` (``bezier.bezier_derivative``'s arithmetic)."""
    s = 1.0 - t
    tp0, tp1 = 1.0, t
    tp2 = tp1 * t
    tp3 = tp2 * t
    tp4 = tp3 * t
    sp1 = s
    sp2 = sp1 * s
    sp3 = sp2 * s
    sp4 = sp3 * s
    base = 6 * j
    acc = 0.0
    acc += 5 * (g[slot, base + 1] - g[slot, base]) * (_COMB4[0] * tp0 * sp4)
    acc += 5 * (g[slot, base + 2] - g[slot, base + 1]) * (_COMB4[1] * tp1 * sp3)
    acc += 5 * (g[slot, base + 3] - g[slot, base + 2]) * (_COMB4[2] * tp2 * sp2)
    acc += 5 * (g[slot, base + 4] - g[slot, base + 3]) * (_COMB4[3] * tp3 * sp1)
    acc += 5 * (g[slot, base + 5] - g[slot, base + 4]) * (_COMB4[4] * tp4 * 1.0)
    return acc


@njit(cache=True)
def bernstein_bases(t: float) -> tuple[float, float, float, float, float, float, float, float, float, float, float]:
    """The Bernstein bases at phase ``t`` that every tick's outputs are evaluated on: degree 5
    (b0 ... b5, the outputs' values) and degree 4 (c0 ... c4, their derivative in phase, on the
    coefficients' differences times 5). :func:`bezier5` and :func:`bezier5_derivative` (the
    blends' offsets, at a gait change only) multiply their powers in ``bezier.bezier``'s order
    instead: the two orders round apart, and each path keeps the bits it has always had."""
    u = 1.0 - t
    t2 = t * t
    t3 = t2 * t
    u2 = u * u
    u3 = u2 * u
    return (u3 * u2, 5.0 * t * u2 * u2, 10.0 * t2 * u3, 10.0 * t3 * u2, 5.0 * t3 * t * u, t3 * t2,
            u2 * u2, 4.0 * t * u3, 6.0 * t2 * u2, 4.0 * t3 * u, t2 * t2)


@njit(cache=True)
def blend_shape(r: float, length: float) -> tuple[float, float, float, float]:
    """The blend's shape functions at ``r`` = (phase - start) / length, clamped to [0, 1]:
    w = 1 - smoothstep(r) carries the position offsets (w(0) = 1, w'(0) = w(1) = w'(1) = 0),
    h = length r (1 - r)^2 the rate offsets (h(0) = 0, dh/dphase(0) = 1, h(1) = h'(1) = 0);
    returns (w, dw/dphase, h, dh/dphase)."""
    r = 0.0 if r < 0.0 else 1.0 if r > 1.0 else r
    u = 1.0 - r
    return 1.0 - r * r * (3.0 - 2.0 * r), -6.0 * r * u / length, length * r * u * u, u * (1.0 - 3.0 * r)


@njit(cache=True)
def _copy_slot(g: np.ndarray, src: int, dst: int) -> None:
    for k in range(SLOT_SIZE):
        g[dst, k] = g[src, k]


@njit(cache=True)
def _same_gait(g: np.ndarray, a: int, b: int) -> bool:
    for k in range(COEFFS):
        if g[a, k] != g[b, k]:
            return False
    return True


@njit(cache=True)
def switch_stance(cfg: np.ndarray, s: np.ndarray, g: np.ndarray) -> None:
    """A touchdown: the other leg stands, the queued gait (and Kd) become active; with
    ``blend_phase`` a changed gait blends in from the one it replaced."""
    s[STANCE] = 1.0 - s[STANCE]
    s[STEPS] += 1.0
    s[TOUCHDOWN] = 1.0
    s[HAS_BLEND] = 0.0
    s[HAS_REPLACED] = 0.0
    s[HAS_REPLACED_BLEND] = 0.0  # an apply_now this very tick: the new gait at once
    if s[HAS_PENDING] != 0.0:
        if cfg[BLEND_PHASE] > 0.0 and not _same_gait(g, PENDING, ACTIVE):
            _copy_slot(g, ACTIVE, REPLACED)
            s[HAS_REPLACED] = 1.0
            s[NEXT_BLEND_LENGTH] = cfg[BLEND_PHASE]
        _copy_slot(g, PENDING, ACTIVE)
        s[HAS_PENDING] = 0.0
    if not np.isnan(s[PENDING_KD]):
        s[KD] = s[PENDING_KD]
        s[PENDING_KD] = np.nan


@njit(cache=True)
def _start_blend(s: np.ndarray, g: np.ndarray, tau: float, p_hip: float) -> None:
    """Right after the gait changed (a touchdown with ``blend_phase``, or ``apply_now``): the
    offsets (rad) from the new gait's desired outputs to the replaced ones at this state (a
    blend in progress included), blended out over the blend length. Within a step the rates
    are matched too (rad per unit of the new gait's phase), so y_d and dy_d/dt are both
    continuous; after a touchdown only the positions are."""
    s[HAS_REPLACED] = 0.0
    had_old_blend = s[HAS_REPLACED_BLEND] != 0.0
    s[HAS_REPLACED_BLEND] = 0.0
    within_step = s[TOUCHDOWN] == 0.0
    s_old = (p_hip - g[REPLACED, P_PLUS]) / g[REPLACED, SPAN]
    t_old = 0.0 if s_old < 0.0 else 1.0 if s_old > 1.0 else s_old
    w = dw = h = dh = 0.0
    if had_old_blend:
        w, dw, h, dh = blend_shape((t_old - s[REPLACED_BLEND + B_START]) / s[REPLACED_BLEND + B_LENGTH],
                                     s[REPLACED_BLEND + B_LENGTH])
    rates_matched = within_step and 0.0 < s_old < 1.0
    ratio = g[ACTIVE, SPAN] / g[REPLACED, SPAN]
    for j in range(4):
        off = s[REPLACED_BLEND + B_OFFSET + j] if had_old_blend else 0.0
        rate = s[REPLACED_BLEND + B_RATE + j] if had_old_blend else 0.0
        offset = bezier5(g, REPLACED, j, t_old) + off * w + rate * h - bezier5(g, ACTIVE, j, tau)
        if rates_matched:  # d/dtau_new = d/dtau_old * span_new / span_old
            new_rate = ((bezier5_derivative(g, REPLACED, j, t_old) + off * dw + rate * dh) * ratio
                        - bezier5_derivative(g, ACTIVE, j, tau))
        else:
            new_rate = 0.0
        s[BLEND + B_OFFSET + j] = offset
        s[BLEND + B_RATE + j] = new_rate
    s[BLEND + B_START] = tau
    s[BLEND + B_LENGTH] = s[NEXT_BLEND_LENGTH]
    s[HAS_BLEND] = 1.0


@njit(cache=True)
def control(cfg: np.ndarray, s: np.ndarray, g: np.ndarray, q: np.ndarray, dq: np.ndarray, out: np.ndarray) -> None:
    """One control tick: joint positions ``q`` and velocities ``dq`` (7 each, ``JOINT_NAMES``
    order) -> ``out``, the four torques (N m) in ``ACTUATED_JOINTS`` order; updates ``s`` (and
    ``g`` at a touchdown). See :mod:`.controller` for the steps."""
    lf = cfg[FEMUR]
    lt = cfg[TIBIA]
    min_phase = cfg[TOUCHDOWN_MIN_PHASE]
    pitch = q[2]
    dpitch = dq[2]
    s[TOUCHDOWN] = 0.0
    sh = sk = wh = wk = phi_f = phi_t = p_hip = x = 0.0
    for _ in range(2):
        if s[STANCE] == 0.0:
            sh, sk, wh, wk = q[3], q[4], q[5], q[6]
        else:
            sh, sk, wh, wk = q[5], q[6], q[3], q[4]
        span = g[ACTIVE, SPAN]
        phi_f = sh - pitch
        phi_t = phi_f - sk
        p_hip = -(lf * sin(phi_f) + lt * sin(phi_t))
        x = (p_hip - g[ACTIVE, P_PLUS]) / span
        if x < min_phase or s[TOUCHDOWN] != 0.0:
            break
        sw_f = wh - pitch
        swing_height = q[1] - lf * cos(sw_f) - lt * cos(sw_f - wk)
        if swing_height > cfg[TOUCHDOWN_HEIGHT]:
            break
        switch_stance(cfg, s, g)
    span = g[ACTIVE, SPAN]

    if s[STANCE] == 0.0:
        dsh, dsk, dwh, dwk = dq[3], dq[4], dq[5], dq[6]
    else:
        dsh, dsk, dwh, dwk = dq[5], dq[6], dq[3], dq[4]
    if x <= 0.0:
        t = 0.0
        dtau = 0.0
    elif x >= 1.0:
        t = 1.0
        dtau = 0.0
    else:
        t = x
        dphi_f = dsh - dpitch
        dp_hip = -(lf * cos(phi_f) * dphi_f + lt * cos(phi_t) * (dphi_f - dsk))
        dtau = dp_hip / span
    rate = cfg[MIN_PHASE_RATE]
    if rate != 0.0:  # the phase (and its rate) no slower than that rate in time since the last tick's
        floor = (0.0 if s[TOUCHDOWN] != 0.0 else s[TAU]) + rate * cfg[TICK]
        if t < floor:
            if floor >= 1.0:
                t, dtau = 1.0, 0.0
            else:
                t, dtau = floor, rate
    s[TAU] = t
    s[TAU_RATE] = dtau
    if s[HAS_REPLACED] != 0.0:
        _start_blend(s, g, t, p_hip)

    b0, b1, b2, b3, b4, b5, c0, c1, c2, c3, c4 = bernstein_bases(t)

    kp = cfg[KP]
    kd = s[KD]
    limit = cfg[TORQUE_LIMIT]
    blending = s[HAS_BLEND] != 0.0
    w = dw = h = dh = 0.0
    if blending:
        length = s[BLEND + B_LENGTH]
        r = (t - s[BLEND + B_START]) / length
        if r >= 1.0:
            s[HAS_BLEND] = 0.0
        w, dw, h, dh = blend_shape(r, length)
    first = 0 if s[STANCE] == 0.0 else 2  # torques in leg order: stance outputs first when left stands
    for j in range(4):
        base = 6 * j
        a0, a1, a2, a3, a4, a5 = (g[ACTIVE, base], g[ACTIVE, base + 1], g[ACTIVE, base + 2], g[ACTIVE, base + 3],
                                  g[ACTIVE, base + 4], g[ACTIVE, base + 5])
        d0 = 5.0 * (a1 - a0)
        d1 = 5.0 * (a2 - a1)
        d2 = 5.0 * (a3 - a2)
        d3 = 5.0 * (a4 - a3)
        d4 = 5.0 * (a5 - a4)
        if j == 0:
            y, dy = sh, dsh
        elif j == 1:
            y, dy = sk, dsk
        elif j == 2:
            y, dy = wh, dwh
        else:
            y, dy = wk, dwk
        if blending:
            off = s[BLEND + B_OFFSET + j]
            rt = s[BLEND + B_RATE + j]
            yd = a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 + a4 * b4 + a5 * b5 + off * w + rt * h
            dyd = (d0 * c0 + d1 * c1 + d2 * c2 + d3 * c3 + d4 * c4 + off * dw + rt * dh) * dtau
        else:
            yd = a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 + a4 * b4 + a5 * b5
            dyd = (d0 * c0 + d1 * c1 + d2 * c2 + d3 * c3 + d4 * c4) * dtau
        tq = kp * (yd - y) + kd * (dyd - dy)
        out[(first + j) % 4] = limit if tq > limit else -limit if tq < -limit else tq


# ------------------------------------------------------------------ a gait's entry checks
GAIT_OK, GAIT_NOT_FINITE, GAIT_IMPACT, GAIT_NO_STEP, GAIT_RANGE = range(5)
""":func:`gait_check`'s answers (GAIT_RANGE + j: output j's coefficients out of range)."""

_SWAP = (2, 3, 0, 1)


@njit(cache=True)
def end_of_step_pitch(alpha: np.ndarray, femur: float, tibia: float) -> float:
    """Torso pitch (rad) at which the end-of-step posture (alpha's last row) has both feet at
    the same height, the swing foot ahead; NaN when both feet are at one point (no step)."""
    sx, sz = foot_position(femur, tibia, 0.0, alpha[20], alpha[21])
    wx, wz = foot_position(femur, tibia, 0.0, alpha[22], alpha[23])
    dx, dz = wx - sx, wz - sz
    if hypot(dx, dz) < 1e-6:
        return np.nan
    # Pitching the torso by q rotates every foot vector by -q (angles from the downward
    # vertical); the stance->swing vector is horizontal and forward when its angle is pi/2.
    beta = atan2(dx, -dz)
    q = beta - pi / 2.0
    return (q + pi) % (2.0 * pi) - pi


@njit(cache=True)
def phase_bounds(alpha: np.ndarray, femur: float, tibia: float) -> tuple[float, float]:
    """(p_plus, p_minus), m: the hip relative to the stance foot at the start and end of a
    step of the gait ``alpha`` (24, coefficient-major); NaNs when it has no step."""
    pitch = end_of_step_pitch(alpha, femur, tibia)
    if np.isnan(pitch):
        return np.nan, np.nan
    sx, sz = foot_position(femur, tibia, pitch, alpha[20], alpha[21])
    wx, wz = foot_position(femur, tibia, pitch, alpha[22], alpha[23])
    p_minus = -sx
    return p_minus - hypot(wx - sx, wz - sz), p_minus


@njit(cache=True)
def gait_check(alpha: np.ndarray, hip_lo: float, hip_hi: float, knee_lo: float, knee_hi: float, femur: float,
               tibia: float, out: np.ndarray) -> int:
    """A gait's entry checks (``controller.validate_alpha``, which words the answer): finite
    coefficients, each output's within its range (out: that output's min and max), the
    impact equalities within 1e-6 rad (out[0]: the violation), a step (out: p_plus, p_minus)."""
    for k in range(24):
        if not np.isfinite(alpha[k]):
            return GAIT_NOT_FINITE
    for j in range(4):
        lo, hi = (knee_lo, knee_hi) if j % 2 else (hip_lo, hip_hi)
        low = high = alpha[j]
        for k in range(1, 6):
            v = alpha[4 * k + j]
            low = min(low, v)
            high = max(high, v)
        if low < lo or high > hi:
            out[0], out[1] = low, high
            return GAIT_RANGE + j
    violation = 0.0
    for j in range(4):
        violation = max(violation, abs(alpha[20 + j] - alpha[_SWAP[j]]))
    if violation > 1e-6:
        out[0] = violation
        return GAIT_IMPACT
    p_plus, p_minus = phase_bounds(alpha, femur, tibia)
    if np.isnan(p_plus):
        return GAIT_NO_STEP
    out[0], out[1] = p_plus, p_minus
    return GAIT_OK


def warm() -> None:
    """Load (or compile) every function here now, not on a node's first tick: a node calls it
    while it starts (loading from numba's cache takes about half a second, which a first
    tick in real time would spend late)."""
    cfg, state, gaits = np.zeros(CONFIG_SIZE), np.zeros(STATE_SIZE), np.zeros((3, SLOT_SIZE))
    cfg[[FEMUR, TIBIA, KP, TORQUE_LIMIT, TOUCHDOWN_MIN_PHASE]] = (0.4, 0.4, 1.0, 1.0, 0.5)
    gaits[:, SPAN] = 1.0
    control(cfg, state, gaits, np.zeros(7), np.zeros(7), np.zeros(4))
    gait_check(np.zeros(24), -1.0, 1.0, -1.0, 1.0, 0.4, 0.4, np.zeros(2))
    foot_position(0.4, 0.4, 0.0, 0.0, 0.0)  # called from Python too (kinematics.foot_from_hip)
