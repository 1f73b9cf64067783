"""The HZD controller: virtual constraints tracked by a PD law, with stance switching.

One call of :meth:`HZDController.compute` is one 1 kHz control tick: joint state in,
four joint torques out, computed by the compiled law (:mod:`.law`, numba) on the
controller's state arrays: the very same code the ROS node, the Gymnasium environment, the
gait optimizer, the benchmarks and the ROS-free loop's compiled inner loop run.

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

from dataclasses import dataclass, field, fields
from enum import IntEnum
from math import isfinite
from typing import Sequence

import numpy as np

from .alpha import N_ALPHA, N_COEFFS, OUTPUTS
from .bezier import bezier, bezier_derivative
from . import law
from .kinematics import LegGeometry, foot_from_hip
from .phase import NO_STEP, PhaseBounds

from rabbit_msgs_py.joints import ACTUATED_JOINTS, JOINT_NAMES  # noqa: F401  (re-exported)


class Leg(IntEnum):
    """Which leg is the stance leg."""

    LEFT = 0
    RIGHT = 1

    def other(self) -> "Leg":
        return Leg.RIGHT if self is Leg.LEFT else Leg.LEFT


_LEFT = Leg.LEFT  # one global lookup on the hot path instead of two


@dataclass(frozen=True)
class ControllerSettings:
    """The HZD controller's own constants (a controller spec's ``controller`` section reads this
    class, every field, and names the robot model beside it; the defaults below are the code's,
    read by no shipped controller).

    kp: proportional gain (N m/rad), the same for the four joints (the paper's fixed Kp).
    torque_limit: actuator saturation (N m), RABBIT's 150 N m peak.
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
        ``blend_phase``): changing the swing leg's path just before it lands can make a
        fast deceleration fall (docs/controller.md, "A gait within the step", measures it).
    min_phase_rate: the phase advances at least this fast (1/s) from one tick to the next:
        a slower measured phase is raised to that floor and its rate to this (0: off).
    """

    kp: float = 3000.0
    torque_limit: float = 150.0
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

    def __post_init__(self) -> None:
        for name in ("kp", "torque_limit", "min_step_length", "max_kd"):
            value = getattr(self, name)
            if not (isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        if not 0.0 < self.touchdown_min_phase < 1.0:
            raise ValueError(f"touchdown_min_phase must be in (0, 1), got {self.touchdown_min_phase!r}")
        if not isfinite(self.touchdown_height):
            raise ValueError(f"touchdown_height must be finite (m), got {self.touchdown_height!r}")
        for name in ("hip_coefficient_range", "knee_coefficient_range"):
            low, high = getattr(self, name)
            if not (isfinite(low) and isfinite(high) and low < high):
                raise ValueError(f"{name} must be finite and ordered low < high (rad), got {[low, high]}")
        if not 0.0 <= self.blend_phase <= 1.0:
            raise ValueError(f"blend_phase must be in [0, 1], got {self.blend_phase!r}")
        if not 0.0 <= self.within_step_blend <= 1.0:
            raise ValueError(f"within_step_blend must be in [0, 1], got {self.within_step_blend!r}")
        if not 0.0 < self.within_step_until <= 1.0:
            raise ValueError(f"within_step_until must be in (0, 1], got {self.within_step_until!r}")
        if not (isfinite(self.min_phase_rate) and self.min_phase_rate >= 0.0):
            raise ValueError(f"min_phase_rate must be finite and >= 0 (1/s), got {self.min_phase_rate!r}")

    def settings(self) -> dict:
        """Every :class:`ControllerSettings` field by name (what ``ControllerConfig(**...)`` takes)."""
        return {f.name: getattr(self, f.name) for f in fields(ControllerSettings)}


@dataclass(frozen=True)
class ControllerConfig(ControllerSettings):
    """The controller's settings on a robot model: ``geometry``, its leg link lengths (m), must
    match the simulated model; ``tick``, the control period (s)."""

    geometry: LegGeometry = field(default_factory=LegGeometry)
    tick: float = 0.001

    def __post_init__(self) -> None:
        super().__post_init__()
        if not (isfinite(self.tick) and self.tick > 0.0):
            raise ValueError(f"tick must be finite and > 0 (s), got {self.tick!r}")


def validate_alpha(alpha: Sequence[float], config: ControllerConfig) -> np.ndarray:
    """Return ``alpha`` as a float 24-vector, or raise ``ValueError`` saying what is wrong:
    wrong size, non-finite entries, impact equalities violated, or no forward step."""
    return _validated(alpha, config)[0]


def _validated(alpha: Sequence[float], config: ControllerConfig) -> tuple[np.ndarray, PhaseBounds]:
    """:func:`validate_alpha`, and the gait's phase bounds (computed on the way by the
    compiled checks, :func:`.law.gait_check`)."""
    arr = np.ascontiguousarray(alpha, dtype=float).reshape(-1)
    if arr.size != N_ALPHA:
        raise ValueError(f"alpha must have {N_ALPHA} coefficients, got {arr.size}")
    out = np.empty(2)
    geometry = config.geometry
    code = law.gait_check(arr, *config.hip_coefficient_range, *config.knee_coefficient_range, geometry.femur,
                          geometry.tibia, out)
    if code == law.GAIT_NOT_FINITE:
        raise ValueError("alpha contains NaN or infinite coefficients")
    if code >= law.GAIT_RANGE:
        j = code - law.GAIT_RANGE
        lo, hi = config.knee_coefficient_range if j % 2 else config.hip_coefficient_range
        raise ValueError(f"alpha {OUTPUTS[j]} coefficients span [{out[0]:.4g}, {out[1]:.4g}] rad,"
                         f" outside the bounds [{lo}, {hi}] rad")
    if code == law.GAIT_IMPACT:
        raise ValueError(f"alpha violates the impact equalities by {out[0]:.3g} rad")
    if code == law.GAIT_NO_STEP:
        raise ValueError(NO_STEP)
    bounds = PhaseBounds(p_plus=float(out[0]), p_minus=float(out[1]))
    if bounds.span < config.min_step_length:
        raise ValueError(
            f"alpha implies a {bounds.span:.3f} m step, shorter than {config.min_step_length} m"
        )
    return arr, bounds


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


def _slot(alpha: np.ndarray, bounds: PhaseBounds) -> np.ndarray:
    """A validated alpha and its phase bounds as a gait slot of :mod:`.law`: the 4 outputs'
    coefficients, p_plus, p_minus, span."""
    row = np.empty(law.SLOT_SIZE)
    row[:law.COEFFS] = alpha.reshape(N_COEFFS, 4).T.reshape(-1)  # output-major
    row[law.P_PLUS], row[law.P_MINUS], row[law.SPAN] = bounds.p_plus, bounds.p_minus, bounds.span
    return row


def _config_array(config: ControllerConfig) -> np.ndarray:
    cfg = np.empty(law.CONFIG_SIZE)
    cfg[law.KP], cfg[law.TORQUE_LIMIT] = config.kp, config.torque_limit
    cfg[law.FEMUR], cfg[law.TIBIA] = config.geometry.femur, config.geometry.tibia
    cfg[law.TOUCHDOWN_MIN_PHASE], cfg[law.TOUCHDOWN_HEIGHT] = config.touchdown_min_phase, config.touchdown_height
    cfg[law.BLEND_PHASE], cfg[law.WITHIN_STEP_BLEND] = config.blend_phase, config.within_step_blend
    cfg[law.MIN_PHASE_RATE], cfg[law.TICK] = config.min_phase_rate, config.tick
    cfg.setflags(write=False)
    return cfg


_ALPHA_ORDER = np.arange(law.COEFFS).reshape(4, 6).T.reshape(-1)
"""Slot entries in alpha's order (coefficient-major): ``alpha = slot[_ALPHA_ORDER]``."""


class HZDController:
    """Stateful HZD tracking controller (ROS-free core).

    ``alpha`` (24-vector, see :mod:`.alpha`) defines the virtual constraints; a new one set
    with :meth:`set_alpha` becomes active at the next touchdown so the constraints stay
    continuous within a step. ``kd`` (N m s/rad) set with :meth:`set_kd` applies at once;
    :meth:`queue_kd` holds it to the next touchdown like alpha (a gait decided for the
    next step, as the policy node and the learning environment use it). :meth:`apply_now`
    makes a gait active within the step, its outputs blended in from the ones in force.

    The state lives in :mod:`.law`'s arrays (``arrays``): :meth:`compute` runs the compiled
    law on them, and the ROS-free loop's compiled inner loop runs the same law on the same
    arrays between its Python events.
    """

    def __init__(
        self,
        alpha: Sequence[float],
        kd: float,
        config: ControllerConfig | None = None,
        stance: Leg = Leg.LEFT,
    ) -> None:
        self.config = config or ControllerConfig()
        self._state = np.zeros(law.STATE_SIZE)
        self._gaits = np.zeros((3, law.SLOT_SIZE))
        self._torques = np.zeros(4)
        self.reset(alpha, kd, stance)

    @property
    def config(self) -> ControllerConfig:
        """The fixed parameters (setting them anew takes effect from the next tick)."""
        return self._config

    @config.setter
    def config(self, config: ControllerConfig) -> None:
        self._config = config
        self._cfg = _config_array(config)

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(cfg, state, gaits): what :func:`.law.control` takes (the state and gaits are live)."""
        return self._cfg, self._state, self._gaits

    # ------------------------------------------------------------------ state
    def reset(self, alpha: Sequence[float], kd: float, stance: Leg = Leg.LEFT) -> None:
        """Make ``alpha`` active immediately, set ``kd`` and the stance leg, zero counters."""
        self._put(law.ACTIVE, *_validated(alpha, self.config))
        s = self._state
        s[:] = 0.0
        s[law.PENDING_KD] = np.nan
        s[law.KD] = validate_kd(kd, self.config)
        s[law.STANCE] = float(Leg(stance))
        s[law.NEXT_BLEND_LENGTH] = self.config.blend_phase

    def _put(self, slot: int, alpha: np.ndarray, bounds: PhaseBounds) -> None:
        """Write a validated alpha (and its phase bounds) into a gait slot."""
        self._gaits[slot] = _slot(alpha, bounds)

    def _slot_alpha(self, slot: int) -> tuple[float, ...]:
        return tuple(self._gaits[slot, _ALPHA_ORDER].tolist())

    def set_alpha(self, alpha: Sequence[float]) -> None:
        """Queue ``alpha`` to take effect at the next touchdown (raises ``ValueError``).
        The gait that would be in force anyway (a policy repeating itself) is not
        validated and digested again."""
        in_force = law.PENDING if self._state[law.HAS_PENDING] else law.ACTIVE
        if isinstance(alpha, tuple) and alpha == self._slot_alpha(in_force):
            return
        self._put(law.PENDING, *_validated(alpha, self.config))
        self._state[law.HAS_PENDING] = 1.0

    def apply_now(self, alpha: Sequence[float], kd: float | None = None) -> None:
        """Make ``alpha`` (and ``kd`` if given) active from the next tick, within the step:
        the desired outputs start where the ones in force are at that state (a blend in
        progress included) and blend into the new gait's over ``within_step_blend`` of
        phase, so they stay continuous. Clears a queued gait. At or after
        ``within_step_until`` of phase the gait is queued for the next touchdown instead (as
        :meth:`set_alpha` and :meth:`queue_kd`). Raises ``ValueError`` (and changes nothing)
        for a bad alpha or Kd."""
        new_kd = None if kd is None else validate_kd(kd, self.config)
        s = self._state
        if s[law.TAU] >= self.config.within_step_until:
            self.set_alpha(alpha)
            if new_kd is not None:
                s[law.PENDING_KD] = new_kd
            return
        s[law.HAS_PENDING] = 0.0
        if not (isinstance(alpha, tuple) and alpha == self._slot_alpha(law.ACTIVE)):
            valid = _validated(alpha, self.config)
            if self.config.within_step_blend > 0.0:
                self._gaits[law.REPLACED] = self._gaits[law.ACTIVE]
                s[law.HAS_REPLACED] = 1.0
                blend, replaced = slice(law.BLEND, law.BLEND + law.BLEND_SIZE), slice(
                    law.REPLACED_BLEND, law.REPLACED_BLEND + law.BLEND_SIZE)
                s[replaced] = s[blend]
                s[law.HAS_REPLACED_BLEND] = s[law.HAS_BLEND]
                s[law.NEXT_BLEND_LENGTH] = self.config.within_step_blend
            else:  # at once: the new gait's own outputs from the next tick
                s[law.HAS_REPLACED] = s[law.HAS_REPLACED_BLEND] = s[law.HAS_BLEND] = 0.0
            self._put(law.ACTIVE, *valid)
        if new_kd is not None:
            s[law.KD] = new_kd
            s[law.PENDING_KD] = np.nan

    def set_kd(self, kd: float) -> None:
        """Set the derivative gain, effective at the next tick (raises ``ValueError``)."""
        self._state[law.KD] = validate_kd(kd, self.config)

    def queue_kd(self, kd: float) -> None:
        """Queue the derivative gain for the next touchdown (raises ``ValueError``)."""
        self._state[law.PENDING_KD] = validate_kd(kd, self.config)

    @property
    def kd(self) -> float:
        """The derivative gain in force (N m s/rad); setting it is :meth:`set_kd`."""
        return float(self._state[law.KD])

    @kd.setter
    def kd(self, kd: float) -> None:
        self.set_kd(kd)

    @property
    def pending_kd(self) -> float | None:
        """Derivative gain waiting for the next touchdown, if any."""
        value = float(self._state[law.PENDING_KD])
        return None if value != value else value

    @property
    def alpha(self) -> tuple[float, ...]:
        """The active 24 coefficients."""
        return self._slot_alpha(law.ACTIVE)

    @property
    def pending_alpha(self) -> tuple[float, ...] | None:
        """Coefficients waiting for the next touchdown, if any."""
        return self._slot_alpha(law.PENDING) if self._state[law.HAS_PENDING] else None

    @property
    def bounds(self) -> PhaseBounds:
        """Phase bounds of the active gait."""
        row = self._gaits[law.ACTIVE]
        return PhaseBounds(float(row[law.P_PLUS]), float(row[law.P_MINUS]))

    @property
    def stance(self) -> Leg:
        """The stance leg."""
        return Leg(int(self._state[law.STANCE]))

    @property
    def steps(self) -> int:
        """Touchdowns since the last :meth:`reset`."""
        return int(self._state[law.STEPS])

    @steps.setter
    def steps(self, value: int) -> None:
        self._state[law.STEPS] = float(value)

    @property
    def tau(self) -> float:
        """The phase at the last :meth:`compute` (0..1)."""
        return float(self._state[law.TAU])

    @tau.setter
    def tau(self, value: float) -> None:
        self._state[law.TAU] = float(value)

    @property
    def tau_rate(self) -> float:
        """d tau / dt (1/s) at the last :meth:`compute`."""
        return float(self._state[law.TAU_RATE])

    @property
    def touchdown(self) -> bool:
        """Whether the last :meth:`compute` switched stance."""
        return bool(self._state[law.TOUCHDOWN])

    # --------------------------------------------------------------- hot path
    def compute(self, q: Sequence[float], dq: Sequence[float]) -> list[float]:
        """One control tick: joint positions ``q`` and velocities ``dq`` (7 each, in
        ``JOINT_NAMES`` order) -> torques (N m) in ``ACTUATED_JOINTS`` order
        (:func:`.law.control`, compiled)."""
        law.control(self._cfg, self._state, self._gaits, np.asarray(q, dtype=np.float64),
                    np.asarray(dq, dtype=np.float64), self._torques)
        return self._torques.tolist()

    def reference(self) -> tuple[list[float], list[float]]:
        """The desired outputs of the last :meth:`compute` (off the hot path, for plotting):
        (y_d in rad, dy_d/dt in rad/s), four each in ``ACTUATED_JOINTS`` order (left hip, left
        knee, right hip, right knee: the stance and swing outputs mapped back to the legs),
        from the phase and its rate of that tick and the gait (and blend) in force."""
        s, g = self._state, self._gaits
        t, dtau = self.tau, self.tau_rate
        w = dw = h = dh = 0.0
        offsets = rates = (0.0,) * 4
        if s[law.HAS_BLEND]:
            start, length = s[law.BLEND + law.B_START], s[law.BLEND + law.B_LENGTH]
            w, dw, h, dh = law.blend_shape(min((t - start) / length, 1.0), length)
            record = s[law.BLEND:law.BLEND + law.BLEND_SIZE]
            offsets, rates = record[law.B_OFFSET:law.B_RATE], record[law.B_RATE:law.B_LENGTH]
        coeffs = g[law.ACTIVE, :law.COEFFS].reshape(4, 6)
        yd = [bezier(c, t) + off * w + rate * h for c, off, rate in zip(coeffs, offsets, rates)]
        dyd = [(bezier_derivative(c, t) + off * dw + rate * dh) * dtau
               for c, off, rate in zip(coeffs, offsets, rates)]
        yd, dyd = [float(v) for v in yd], [float(v) for v in dyd]
        if self.stance is _LEFT:
            return yd, dyd
        return yd[2:] + yd[:2], dyd[2:] + dyd[:2]
