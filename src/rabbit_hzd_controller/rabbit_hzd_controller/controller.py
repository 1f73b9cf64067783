"""The HZD controller: virtual constraints tracked by a PD law, with stance switching.

One call of :meth:`HZDController.compute` is one 1 kHz control tick: joint state in,
four joint torques out. It is written in plain Python floats (no numpy on the hot path,
see ``scripts/bench_sim.py``) and is the very same code the ROS node, the Gymnasium
environment, the gait optimizer and the benchmarks run.

Joint state order (the model's ``qpos``/``qvel`` order, also the ``/joint_states`` order):
``JOINT_NAMES = (x, z, torso_pitch, left_hip, left_knee, right_hip, right_knee)``; x, z
are the world position of the hip (m), the rest angles (rad), see :mod:`.kinematics`.
Torques come out in actuator order ``ACTUATED_JOINTS`` (N m).

Per tick:
1. relabel the legs into (stance hip, stance knee, swing hip, swing knee);
2. if the phase has passed ``touchdown_min_phase`` and the swing foot is at or below
   ``touchdown_height`` above the ground, switch stance (exactly once per step: right
   after a switch the new swing foot is at phase ~0) and make the pending alpha active;
3. tau and d tau/dt from the stance hip position (:mod:`.phase`);
4. desired outputs ``y_d(tau, alpha)`` and ``dy_d/dt = dy_d/dtau * dtau/dt``;
5. ``u = Kp (y_d - y) + Kd (dy_d - dy)``, saturated to the torque limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from math import cos, isfinite, sin
from typing import Sequence

import numpy as np

from .alpha import N_ALPHA, OUTPUTS, alpha_matrix, impact_violation
from .bezier import bezier, bezier_derivative
from .kinematics import LegGeometry, foot_from_hip
from .phase import PhaseBounds, phase_bounds_from_alpha

from rabbit_msgs_py.joints import ACTUATED_JOINTS, JOINT_NAMES  # noqa: F401  (re-exported)


class Leg(IntEnum):
    """Which leg is the stance leg."""

    LEFT = 0
    RIGHT = 1

    def other(self) -> "Leg":
        return Leg.RIGHT if self is Leg.LEFT else Leg.LEFT


_LEFT = Leg.LEFT  # one global lookup on the hot path instead of two


@dataclass(frozen=True)
class ControllerConfig:
    """Fixed parameters of the HZD controller.

    kp: proportional gain (N m/rad), the same for the four joints (the paper's fixed Kp).
    torque_limit: actuator saturation (N m), RABBIT's 150 N m peak.
    geometry: leg link lengths (m), must match the simulated model.
    touchdown_min_phase: the swing foot may only touch down once the unsaturated phase has
        reached this value (debounces scuffing right after a switch).
    touchdown_height: swing-foot tip height above the ground (m) at or below which the
        foot counts as touching down.
    min_step_length: alpha whose implied step is shorter than this (m) is rejected.
    hip_coefficient_range, knee_coefficient_range: bounds (rad) on the Bezier
        coefficients of the hip and knee outputs. The coefficients are joint waypoints, so
        their range is the model's joint range (hip +-1.3 rad, knee 0..1.6 rad) widened
        by 0.3 rad: a waypoint may lie a little outside the curve it shapes. alpha outside
        these bounds is rejected.
    max_kd: upper bound on the derivative gain (N m s/rad).
    blend_phase: when a touchdown brings a different gait, the desired outputs start where
        the old gait's would have been at that state and blend into the new gait's over this
        much phase (smoothstep; 0 = off: the new gait's outputs at once, a jump of up to
        0.5 rad between library gaits).
    within_step_blend: a gait applied within a step (:meth:`HZDController.apply_now`, the
        policy deciding every N ticks) blends in this way, over this much phase, so the
        desired outputs stay continuous; 0 = no blend: the new gait's outputs from the next
        tick, as the paper applies alpha (a jump in the desired outputs).
    within_step_until: a gait :meth:`HZDController.apply_now` receives at or after this
        phase waits for the next touchdown instead (and blends in there over
        ``blend_phase``): changing the swing leg's path just before it lands made the
        decelerations from 1.4-1.5 m/s commanded at 3/4 of a step fall (measured: 4 of 72
        decelerations fell for the learned policy with 1.0, none with 0.6 and a 0.2
        touchdown blend).
    """

    kp: float = 3000.0
    torque_limit: float = 150.0
    geometry: LegGeometry = field(default_factory=LegGeometry)
    touchdown_min_phase: float = 0.5
    touchdown_height: float = 0.0
    min_step_length: float = 0.05
    hip_coefficient_range: tuple[float, float] = (-1.6, 1.6)
    knee_coefficient_range: tuple[float, float] = (-0.3, 1.9)
    max_kd: float = 300.0
    blend_phase: float = 0.2
    within_step_blend: float = 0.2
    within_step_until: float = 0.6
    min_phase_rate: float = 0.0
    tick: float = 0.001

    def __post_init__(self) -> None:
        for name in ("kp", "torque_limit", "min_step_length", "max_kd"):
            value = getattr(self, name)
            if not (isfinite(value) and value > 0.0):
                raise ValueError(f"ControllerConfig.{name} must be finite and > 0, got {value}")
        if not 0.0 < self.touchdown_min_phase < 1.0:
            raise ValueError("ControllerConfig.touchdown_min_phase must be in (0, 1)")
        if not 0.0 <= self.blend_phase <= 1.0:
            raise ValueError("ControllerConfig.blend_phase must be in [0, 1]")
        if not 0.0 <= self.within_step_blend <= 1.0:
            raise ValueError("ControllerConfig.within_step_blend must be in [0, 1]")
        if not 0.0 < self.within_step_until <= 1.0:
            raise ValueError("ControllerConfig.within_step_until must be in (0, 1]")
        if not (isfinite(self.min_phase_rate) and self.min_phase_rate >= 0.0):
            raise ValueError("ControllerConfig.min_phase_rate must be finite and >= 0 (1/s)")
        if not (isfinite(self.tick) and self.tick > 0.0):
            raise ValueError("ControllerConfig.tick must be finite and > 0 (s)")


@dataclass(frozen=True)
class _Outputs:
    """Pre-digested alpha for the hot path: per output, the 6 coefficients and the 5
    scaled differences ``M (a[k+1] - a[k])`` of the derivative polynomial."""

    alpha: tuple[float, ...]
    coeffs: tuple[tuple[float, ...], ...]
    diffs: tuple[tuple[float, ...], ...]
    bounds: PhaseBounds
    p_plus: float  # bounds.p_plus and bounds.span as plain attributes (span is a property)
    span: float


def validate_alpha(alpha: Sequence[float], config: ControllerConfig) -> np.ndarray:
    """Return ``alpha`` as a float 24-vector, or raise ``ValueError`` saying what is wrong:
    wrong size, non-finite entries, impact equalities violated, or no forward step."""
    arr = np.asarray(alpha, dtype=float).reshape(-1)
    if arr.size != N_ALPHA:
        raise ValueError(f"alpha must have {N_ALPHA} coefficients, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("alpha contains NaN or infinite coefficients")
    matrix = alpha_matrix(arr)
    for j, output in enumerate(OUTPUTS):
        lo, hi = config.knee_coefficient_range if j % 2 else config.hip_coefficient_range
        column = matrix[:, j]
        if column.min() < lo or column.max() > hi:
            raise ValueError(
                f"alpha {output} coefficients span [{column.min():.4g}, {column.max():.4g}] rad,"
                f" outside the bounds [{lo}, {hi}] rad"
            )
    violation = impact_violation(arr)
    if violation > 1e-6:
        raise ValueError(f"alpha violates the impact equalities by {violation:.3g} rad")
    bounds = phase_bounds_from_alpha(arr, config.geometry)
    if bounds.span < config.min_step_length:
        raise ValueError(
            f"alpha implies a {bounds.span:.3f} m step, shorter than {config.min_step_length} m"
        )
    return arr


def validate_kd(kd: float, config: ControllerConfig | None = None) -> float:
    """Return ``kd`` as a float, or raise ``ValueError`` unless 0 <= kd <= ``max_kd``."""
    max_kd = (config or ControllerConfig()).max_kd
    value = float(kd)
    if not isfinite(value) or not 0.0 <= value <= max_kd:
        raise ValueError(f"Kd must be finite and in [0, {max_kd}] N m s/rad, got {kd}")
    return value


def infer_stance(q: Sequence[float], geometry: LegGeometry | None = None) -> Leg:
    """The stance leg of a state ``q`` (``JOINT_NAMES`` order): the lower foot, or, when both
    feet are within 5 mm of each other in height (double support at a touchdown), the
    foot further forward (the one that has just landed). Used when a controller starts
    or restarts on a robot that is already walking."""
    geometry = geometry or LegGeometry()
    left = foot_from_hip(geometry, q[2], q[3], q[4])
    right = foot_from_hip(geometry, q[2], q[5], q[6])
    if abs(left[1] - right[1]) > 0.005:
        return Leg.LEFT if left[1] < right[1] else Leg.RIGHT
    return Leg.LEFT if left[0] >= right[0] else Leg.RIGHT


_BlendState = tuple[float, tuple[float, ...], tuple[float, ...], float]
"""A blend in progress: (phase at its start, position offsets rad, rate offsets rad per
unit phase, length in phase)."""


def _blend_shape(r: float, length: float) -> tuple[float, float, float, float]:
    """The blend's shape functions at ``r`` = (phase - start) / length, clamped to [0, 1]:
    w = 1 - smoothstep(r) carries the position offsets (w(0) = 1, w'(0) = w(1) = w'(1) = 0),
    h = length r (1 - r)^2 the rate offsets (h(0) = 0, dh/dphase(0) = 1, h(1) = h'(1) = 0);
    returns (w, dw/dphase, h, dh/dphase)."""
    r = 0.0 if r < 0.0 else 1.0 if r > 1.0 else r
    u = 1.0 - r
    return 1.0 - r * r * (3.0 - 2.0 * r), -6.0 * r * u / length, length * r * u * u, u * (1.0 - 3.0 * r)


def _digest(alpha: np.ndarray, config: ControllerConfig) -> _Outputs:
    m = alpha_matrix(alpha)
    coeffs = tuple(tuple(float(v) for v in m[:, j]) for j in range(4))
    diffs = tuple(tuple(5.0 * (c[k + 1] - c[k]) for k in range(5)) for c in coeffs)
    bounds = phase_bounds_from_alpha(alpha, config.geometry)
    return _Outputs(
        alpha=tuple(float(v) for v in alpha),
        coeffs=coeffs,
        diffs=diffs,
        bounds=bounds,
        p_plus=bounds.p_plus,
        span=bounds.span,
    )


class HZDController:
    """Stateful HZD tracking controller (ROS-free core).

    ``alpha`` (24-vector, see :mod:`.alpha`) defines the virtual constraints; a new one set
    with :meth:`set_alpha` becomes active at the next touchdown so the constraints stay
    continuous within a step. ``kd`` (N m s/rad) set with :meth:`set_kd` applies at once;
    :meth:`queue_kd` holds it to the next touchdown like alpha (a gait decided for the
    next step, as the policy node and the learning environment use it). :meth:`apply_now`
    makes a gait active within the step, its outputs blended in from the ones in force.
    """

    def __init__(
        self,
        alpha: Sequence[float],
        kd: float,
        config: ControllerConfig | None = None,
        stance: Leg = Leg.LEFT,
    ) -> None:
        self.config = config or ControllerConfig()
        self.reset(alpha, kd, stance)

    # ------------------------------------------------------------------ state
    def reset(self, alpha: Sequence[float], kd: float, stance: Leg = Leg.LEFT) -> None:
        """Make ``alpha`` active immediately, set ``kd`` and the stance leg, zero counters."""
        self._active = _digest(validate_alpha(alpha, self.config), self.config)
        self._pending: _Outputs | None = None
        self._pending_kd: float | None = None
        self.kd = validate_kd(kd, self.config)
        self.stance = Leg(stance)
        self.steps = 0
        self.tau = 0.0
        self.tau_rate = 0.0  # d tau / dt (1/s) at the last compute
        self.touchdown = False
        self._replaced: _Outputs | None = None  # the gait a touchdown (or apply_now) just replaced
        self._replaced_blend: _BlendState | None = None  # its blend then, if any
        self._blend: _BlendState | None = None
        self._blend_length = self.config.blend_phase  # of the next blend to start

    def set_alpha(self, alpha: Sequence[float]) -> None:
        """Queue ``alpha`` to take effect at the next touchdown (raises ``ValueError``).
        The gait that would be in force anyway (a policy repeating itself) is not
        validated and digested again."""
        in_force = self._pending if self._pending is not None else self._active
        if isinstance(alpha, tuple) and alpha == in_force.alpha:
            return
        self._pending = _digest(validate_alpha(alpha, self.config), self.config)

    def apply_now(self, alpha: Sequence[float], kd: float | None = None) -> None:
        """Make ``alpha`` (and ``kd`` if given) active from the next tick, within the step:
        the desired outputs start where the ones in force are at that state (a blend in
        progress included) and blend into the new gait's over ``within_step_blend`` of
        phase, so they stay continuous. Clears a queued gait. At or after
        ``within_step_until`` of phase the gait is queued for the next touchdown instead (as
        :meth:`set_alpha` and :meth:`queue_kd`). Raises ``ValueError`` (and changes nothing)
        for a bad alpha or Kd."""
        new_kd = None if kd is None else validate_kd(kd, self.config)
        if self.tau >= self.config.within_step_until:
            self.set_alpha(alpha)
            if new_kd is not None:
                self._pending_kd = new_kd
            return
        self._pending = None
        if not (isinstance(alpha, tuple) and alpha == self._active.alpha):
            digested = _digest(validate_alpha(alpha, self.config), self.config)
            if self.config.within_step_blend > 0.0:
                self._replaced, self._replaced_blend = self._active, self._blend
                self._blend_length = self.config.within_step_blend
            else:  # at once: the new gait's own outputs from the next tick
                self._replaced = self._replaced_blend = self._blend = None
            self._active = digested
        if new_kd is not None:
            self.kd = new_kd
            self._pending_kd = None

    def set_kd(self, kd: float) -> None:
        """Set the derivative gain, effective at the next tick (raises ``ValueError``)."""
        self.kd = validate_kd(kd, self.config)

    def queue_kd(self, kd: float) -> None:
        """Queue the derivative gain for the next touchdown (raises ``ValueError``)."""
        self._pending_kd = validate_kd(kd, self.config)

    @property
    def pending_kd(self) -> float | None:
        """Derivative gain waiting for the next touchdown, if any."""
        return self._pending_kd

    @property
    def alpha(self) -> tuple[float, ...]:
        """The active 24 coefficients."""
        return self._active.alpha

    @property
    def pending_alpha(self) -> tuple[float, ...] | None:
        """Coefficients waiting for the next touchdown, if any."""
        return None if self._pending is None else self._pending.alpha

    @property
    def bounds(self) -> PhaseBounds:
        """Phase bounds of the active gait."""
        return self._active.bounds

    # --------------------------------------------------------------- hot path
    def compute(self, q: Sequence[float], dq: Sequence[float]) -> list[float]:
        """One control tick: joint positions ``q`` and velocities ``dq`` (7 each, in
        ``JOINT_NAMES`` order) -> torques (N m) in ``ACTUATED_JOINTS`` order."""
        cfg = self.config
        geometry = cfg.geometry
        lf = geometry.femur
        lt = geometry.tibia
        min_phase = cfg.touchdown_min_phase
        pitch = q[2]
        dpitch = dq[2]
        self.touchdown = False
        for _ in range(2):
            if self.stance is _LEFT:
                sh, sk, wh, wk = q[3], q[4], q[5], q[6]
            else:
                sh, sk, wh, wk = q[5], q[6], q[3], q[4]
            out = self._active
            span = out.span
            phi_f = sh - pitch
            phi_t = phi_f - sk
            p_hip = -(lf * sin(phi_f) + lt * sin(phi_t))
            s = (p_hip - out.p_plus) / span
            if s < min_phase or self.touchdown:
                break
            sw_f = wh - pitch
            swing_height = q[1] - lf * cos(sw_f) - lt * cos(sw_f - wk)
            if swing_height > cfg.touchdown_height:
                break
            self._switch_stance()

        if self.stance is _LEFT:
            dsh, dsk, dwh, dwk = dq[3], dq[4], dq[5], dq[6]
        else:
            dsh, dsk, dwh, dwk = dq[5], dq[6], dq[3], dq[4]
        if s <= 0.0:
            t = 0.0
            dtau = 0.0
        elif s >= 1.0:
            t = 1.0
            dtau = 0.0
        else:
            t = s
            dphi_f = dsh - dpitch
            dp_hip = -(lf * cos(phi_f) * dphi_f + lt * cos(phi_t) * (dphi_f - dsk))
            dtau = dp_hip / span
        if cfg.min_phase_rate:  # off by default: one attribute read on the hot path
            t, dtau = self._phase_in_time(t, dtau)
        self.tau = t
        self.tau_rate = dtau
        if self._replaced is not None:
            self._start_blend(t, (sh, sk, wh, wk), p_hip)

        # Bernstein bases of degree 5 (values) and 4 (derivative).
        u = 1.0 - t
        t2 = t * t
        t3 = t2 * t
        u2 = u * u
        u3 = u2 * u
        b0 = u3 * u2
        b1 = 5.0 * t * u2 * u2
        b2 = 10.0 * t2 * u3
        b3 = 10.0 * t3 * u2
        b4 = 5.0 * t3 * t * u
        b5 = t3 * t2
        c0 = u2 * u2
        c1 = 4.0 * t * u3
        c2 = 6.0 * t2 * u2
        c3 = 4.0 * t3 * u
        c4 = t2 * t2

        kp = cfg.kp
        kd = self.kd
        limit = cfg.torque_limit
        torques = []
        blend = self._blend
        if blend is None:
            for (a0, a1, a2, a3, a4, a5), (d0, d1, d2, d3, d4), y, dy in zip(
                    out.coeffs, out.diffs, (sh, sk, wh, wk), (dsh, dsk, dwh, dwk)):
                yd = a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 + a4 * b4 + a5 * b5
                dyd = (d0 * c0 + d1 * c1 + d2 * c2 + d3 * c3 + d4 * c4) * dtau
                tq = kp * (yd - y) + kd * (dyd - dy)
                torques.append(limit if tq > limit else -limit if tq < -limit else tq)
        else:  # the same law on the blended outputs y_d + c(tau) (see _blend_shape)
            r = (t - blend[0]) / blend[3]
            if r >= 1.0:
                self._blend = None
            w, dw, h, dh = _blend_shape(r, blend[3])
            for (a0, a1, a2, a3, a4, a5), (d0, d1, d2, d3, d4), y, dy, off, rate in zip(
                    out.coeffs, out.diffs, (sh, sk, wh, wk), (dsh, dsk, dwh, dwk), blend[1], blend[2]):
                yd = a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 + a4 * b4 + a5 * b5 + off * w + rate * h
                dyd = (d0 * c0 + d1 * c1 + d2 * c2 + d3 * c3 + d4 * c4 + off * dw + rate * dh) * dtau
                tq = kp * (yd - y) + kd * (dyd - dy)
                torques.append(limit if tq > limit else -limit if tq < -limit else tq)
        if self.stance is _LEFT:
            return torques
        return [torques[2], torques[3], torques[0], torques[1]]

    def reference(self) -> tuple[list[float], list[float]]:
        """The desired outputs of the last :meth:`compute` (off the hot path, for plotting):
        (y_d in rad, dy_d/dt in rad/s), four each in ``ACTUATED_JOINTS`` order (left hip, left
        knee, right hip, right knee: the stance and swing outputs mapped back to the legs),
        from the phase and its rate of that tick and the gait (and blend) in force."""
        t, dtau = self.tau, self.tau_rate
        out, blend = self._active, self._blend
        w = dw = h = dh = 0.0
        offsets = rates = (0.0,) * 4
        if blend is not None:
            w, dw, h, dh = _blend_shape(min((t - blend[0]) / blend[3], 1.0), blend[3])
            offsets, rates = blend[1], blend[2]
        yd = [bezier(c, t) + off * w + rate * h for c, off, rate in zip(out.coeffs, offsets, rates)]
        dyd = [(bezier_derivative(c, t) + off * dw + rate * dh) * dtau
               for c, off, rate in zip(out.coeffs, offsets, rates)]
        if self.stance is _LEFT:
            return yd, dyd
        return yd[2:] + yd[:2], dyd[2:] + dyd[:2]

    def _phase_in_time(self, t: float, dtau: float) -> tuple[float, float]:
        """``min_phase_rate``: the phase (and its rate) no slower than that rate in time
        since the last tick's phase (0 right after a touchdown), saturated at 1."""
        rate = self.config.min_phase_rate
        floor = (0.0 if self.touchdown else self.tau) + rate * self.config.tick
        if t >= floor:
            return t, dtau
        return (1.0, 0.0) if floor >= 1.0 else (floor, rate)

    def _start_blend(self, tau: float, outputs: tuple[float, ...], p_hip: float) -> None:
        """Right after the gait changed (a touchdown with ``blend_phase``, or
        :meth:`apply_now`): the offsets (rad) from the new gait's desired outputs to the
        replaced ones at this state (a blend in progress included), blended out over the
        blend length. Within a step (the replaced gait was not ended by a touchdown) the
        rates are matched too (rad per unit of the new gait's phase), so y_d and dy_d/dt
        are both continuous; after a touchdown only the positions are (the impact changed
        the velocities anyway)."""
        old, self._replaced = self._replaced, None
        old_blend, self._replaced_blend = self._replaced_blend, None
        within_step = not self.touchdown
        s_old = (p_hip - old.p_plus) / old.span
        t_old = 0.0 if s_old < 0.0 else 1.0 if s_old > 1.0 else s_old
        if old_blend is None:
            w = dw = h = dh = 0.0
            old_offsets = old_rates = (0.0,) * 4
        else:
            w, dw, h, dh = _blend_shape((t_old - old_blend[0]) / old_blend[3], old_blend[3])
            old_offsets, old_rates = old_blend[1], old_blend[2]
        new = self._active
        offsets = tuple(bezier(old_c, t_old) + off * w + rate * h - bezier(new_c, tau)
                        for old_c, new_c, off, rate in zip(old.coeffs, new.coeffs, old_offsets, old_rates))
        if within_step and 0.0 < s_old < 1.0:  # d/dtau_new = d/dtau_old * span_new / span_old
            ratio = new.span / old.span
            rates = tuple((bezier_derivative(old_c, t_old) + off * dw + rate * dh) * ratio
                          - bezier_derivative(new_c, tau)
                          for old_c, new_c, off, rate in zip(old.coeffs, new.coeffs, old_offsets, old_rates))
        else:
            rates = (0.0,) * 4
        self._blend = (tau, offsets, rates, self._blend_length)

    def _switch_stance(self) -> None:
        self.stance = self.stance.other()
        self.steps += 1
        self.touchdown = True
        self._blend = None
        self._replaced = self._replaced_blend = None  # an apply_now this very tick: the new gait at once
        if self._pending is not None:
            if self.config.blend_phase > 0.0 and self._pending.alpha != self._active.alpha:
                self._replaced = self._active
                self._blend_length = self.config.blend_phase
            self._active = self._pending
            self._pending = None
        if self._pending_kd is not None:
            self.kd = self._pending_kd
            self._pending_kd = None
