"""The step-to-step return map of RABBIT walking under a gait policy, for :mod:`.poincare`.

Section: mid-stance, where the controller's phase tau crosses ``section_phase`` (0.5),
the crossing interpolated between the two 1 ms samples around it (a crossing taken at
the first sample past it would jump by a tick). There the stance foot is planted, so
the robot's state is the single-support state: 10 coordinates in stance-relative
order — torso pitch, stance hip, stance knee, swing hip, swing knee (rad) and their
rates (rad/s). The hip's position and velocity follow from the stance foot: it stays
where it was captured and keeps its captured velocity (the sphere foot rolls), so a
perturbed state is always one the robot can be in.

A policy that uses the measured speed (HZD-RL) has memory, and it is part of the state:
the gait in force was chosen from the mean speed of the step before last, the queued
gait (applied at the next touchdown) from the last step's mean, and the current step's
running mean decides the next one. With ``feedback`` these three speeds (m/s) are
coordinates 11-13, and every evaluation re-derives both gaits from them through the
policy. Without it (classic HZD: the gait depends on the commanded speed only) the map
is the 10-D map of one fixed gait. A policy with a memory of its own (the speed-error
integral, the last action: ``features`` memory or body, classic with ``speed_integral``)
decides every evaluation from that memory as it was on the cycle (a copy captured with the
state, restored with it), so the map is a function of its coordinates; the memory's own
slow mode (the integral's) is not one of them.

Every evaluation of the map restores the *full* MuJoCo state captured on the cycle
(``mj_setState`` with ``mjSTATE_FULLPHYSICS | mjSTATE_WARMSTART``: time, positions,
velocities and the constraint solver's warm start, without which the next step depends on
what ran before at the 1e-15 level), a copy of the captured controller, applies the
coordinates and simulates to the next crossing, one step later, swapping the legs back
into stance-relative order. The ticks run compiled (to the touchdown, then to just short of
the section; the last few, the crossing among them, run alone:
:meth:`WalkReturnMap.run_to_section`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from rabbit_hzd_controller.controller import Leg
from rabbit_sim.physics.model import ModelOptions

from rabbit_policy.evaluation.poincare import PoincareAnalysis, RegressionFit, regression_fit, section_crossing
from rabbit_policy.runtime.policies import Policy, copy_policy, first_command, reset_policy
from rabbit_policy.runtime.speed_window import Observation
from rabbit_policy.experiment.loop import ClosedLoop
from rabbit_policy.experiment.scenario import Scenario

SECTION_MARGIN = 0.01
"""Phase short of the section where the compiled ticks hand over to single ones (2-4 ticks of
walking; a tick that jumps past the section is replayed, :meth:`WalkReturnMap._short_of_section`)."""
STANCE_JOINTS = {Leg.LEFT: (3, 4, 5, 6), Leg.RIGHT: (5, 6, 3, 4)}  # stance hip, knee, swing hip, knee
ROBOT_DIMENSION = 10
MEMORY_DIMENSION = 3


class StepFailed(RuntimeError):
    """The robot did not reach the next section (it fell or stalled)."""


@dataclass
class _Capture:
    state: np.ndarray
    controller: tuple[np.ndarray, ...]  # the controller's state and gait arrays (HZDController.arrays)
    foot: np.ndarray  # stance foot site position (world, m)
    foot_velocity: np.ndarray  # its linear velocity (world, m/s)
    step_count: int  # ticks of the current step up to the section
    policy: Policy  # the policy with its memory (speed integral, last action) as on the cycle
    tick: int  # the simulator's tick count (its sim time; MuJoCo's time is in ``state``)


@dataclass(frozen=True)
class StabilityResult:
    """Linear stability at one commanded speed: the analysis (fixed point, Jacobian), the
    perturbed runs that fell or stalled, the natural step-to-step jitter of the section
    state (std per coordinate) and the measured decay of a perturbation per step."""

    analysis: PoincareAnalysis
    fit: RegressionFit
    jitter: np.ndarray
    decay_per_step: float | None

    def to_dict(self) -> dict:
        return {**self.analysis.to_dict(), "pairs_used": self.fit.used, "pairs_failed": self.fit.failed,
                "jitter_max": float(self.jitter.max()), "decay_per_step": self.decay_per_step}


class WalkReturnMap:
    """P: section state -> section state one step later, for ``policy`` commanded
    ``desired_speed`` (m/s). Starts on the policy's first gait and walks ``settle_steps``
    steps onto the cycle before capturing it. ``section_margin``: the phase short of the
    section where the compiled ticks hand over to single ones (0: every step's crossing tick
    is replayed; the result is the same, bit for bit)."""

    def __init__(self, policy: Policy, desired_speed: float, feedback: bool, model: ModelOptions = ModelOptions(),
                 section_phase: float = 0.5, settle_steps: int = 40, max_step_time: float = 2.0,
                 section_margin: float = SECTION_MARGIN) -> None:
        self.policy = copy_policy(policy)  # its memory is the map's: the caller's policy is not touched
        reset_policy(self.policy)  # and starts afresh, whatever walked with it before
        self.desired_speed = float(desired_speed)
        self.feedback = feedback
        # the closed loop without a policy: the map decides the gaits itself (below), because
        # the policy's memory is part of the map's state and must be set by its coordinates
        self.loop = ClosedLoop(Scenario.constant(desired_speed, model=model), start=first_command(self.policy, desired_speed))
        self.model = self.loop.model
        self.controller = self.loop.controller
        self.data = self.loop.data
        self.section_phase = section_phase
        self.section_margin = section_margin
        self.max_ticks = int(round(max_step_time / self.model.opt.timestep))
        self._feet = {Leg.LEFT: self.model.site("left_foot").id, Leg.RIGHT: self.model.site("right_foot").id}
        # the whole physics state *and* the solver's warm start (not part of FULLPHYSICS): restored, a
        # state steps to the same next state whatever ran before
        self._spec = mujoco.mjtState.mjSTATE_FULLPHYSICS | mujoco.mjtState.mjSTATE_WARMSTART
        self._size = mujoco.mj_stateSize(self.model, self._spec)
        self._jac = np.zeros((3, self.model.nv))
        self._before, self._after = np.zeros(self._size), np.zeros(self._size)  # full states around a tick
        # policy memory: mean speeds (m/s) behind the active and the queued gait, and the
        # running sum / tick count of the current step
        self.active_speed = self.pending_speed = self.desired_speed
        self.step_sum, self.step_count = 0.0, 0
        for _ in range(settle_steps):
            self.run_to_section()
        self.capture()

    @property
    def dimension(self) -> int:
        return ROBOT_DIMENSION + (MEMORY_DIMENSION if self.feedback else 0)

    # ------------------------------------------------------------------ state
    def coordinates(self) -> np.ndarray:
        """The current section state (see the module docstring)."""
        q, dq = self.data.qpos, self.data.qvel
        idx = [2, *STANCE_JOINTS[self.controller.stance]]
        robot = np.concatenate([q[idx], dq[idx]])
        if not self.feedback:
            return robot
        running = self.step_sum / self.step_count if self.step_count else self.pending_speed
        return np.concatenate([robot, [self.active_speed, self.pending_speed, running]])

    def capture(self) -> None:
        """Make the current (on-cycle) state the one every evaluation starts from."""
        state = np.zeros(self._size)
        mujoco.mj_getState(self.model, self.data, state, self._spec)
        site = self._feet[self.controller.stance]
        mujoco.mj_jacSite(self.model, self.data, self._jac, None, site)
        self._capture = _Capture(state, self._controller_state(), self.data.site_xpos[site].copy(),
                                 self._jac @ self.data.qvel, self.step_count, copy_policy(self.policy),
                                 self.loop.sim.tick)

    def _controller_state(self) -> tuple[np.ndarray, ...]:
        """A copy of what the controller's ticks change: its state and gait arrays."""
        return tuple(a.copy() for a in self.controller.arrays[1:])

    def _restore_controller(self, saved: tuple[np.ndarray, ...]) -> None:
        for live, copied in zip(self.controller.arrays[1:], saved):
            live[...] = copied

    def _act(self, mean_speed: float):
        """The policy's gait for a step whose mean speed was ``mean_speed`` (m/s); a policy that
        reads the body state sees the current one (once per step here: an approximation for a
        policy deciding every N ticks, as for memory)."""
        v_d = self.desired_speed
        body = self.loop.body_state() if getattr(self.policy, "needs_body", False) else None
        return self.policy.act(Observation(v_d, mean_speed, v_d - mean_speed, body))

    def _apply(self, x: np.ndarray) -> None:
        """Restore the captured state and controller, then set the coordinates ``x``."""
        model, data, cap = self.model, self.data, self._capture
        mujoco.mj_setState(model, data, cap.state, self._spec)
        self.loop.sim.tick = cap.tick
        self._restore_controller(cap.controller)
        self.policy = copy_policy(cap.policy)  # a policy with memory decides from the cycle's memory
        stance = self.controller.stance
        if self.feedback:
            self.active_speed, self.pending_speed, running = (float(v) for v in x[ROBOT_DIMENSION:])
            active, pending = self._act(self.active_speed), self._act(self.pending_speed)
            steps = self.controller.steps
            self.controller.reset(active.alpha, active.kd, stance)
            self.controller.steps = steps
            self.controller.set_alpha(pending.alpha)
            self.controller.queue_kd(pending.kd)
            self.step_count = cap.step_count
            self.step_sum = running * cap.step_count
        idx = [2, *STANCE_JOINTS[stance]]
        data.qpos[idx] = x[:5]
        data.qvel[idx] = x[5:ROBOT_DIMENSION]
        site = self._feet[stance]
        mujoco.mj_kinematics(model, data)
        data.qpos[0] += cap.foot[0] - data.site_xpos[site][0]  # slide joints: translate the hip
        data.qpos[1] += cap.foot[2] - data.site_xpos[site][2]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_jacSite(model, data, self._jac, None, site)
        data.qvel[0] = data.qvel[1] = 0.0
        relative = self._jac @ data.qvel  # foot velocity from the rotations alone
        data.qvel[0] = cap.foot_velocity[0] - relative[0]
        data.qvel[1] = cap.foot_velocity[2] - relative[2]
        mujoco.mj_forward(model, data)

    def _ticks(self, limit: int) -> int:
        """Up to ``limit`` closed-loop ticks at once (:meth:`ClosedLoop.advance`: compiled, ending
        at a touchdown); returns the ticks run (:meth:`_commit`)."""
        return self._commit(*self.loop.advance(limit))

    def _commit(self, speeds: np.ndarray, stop: bool) -> int:
        """Account for ticks run: their hip speeds (m/s) join the step's running sum tick by
        tick; at a touchdown the policy decides the gait after next. Returns how many ran;
        raises :class:`StepFailed` when the robot fell."""
        total = self.step_sum
        for v in speeds.tolist():  # one by one, in order: the sum a tick-by-tick walk forms
            total += v
        self.step_sum = total
        self.step_count += len(speeds)
        if self.controller.touchdown:
            mean = self.step_sum / self.step_count
            command = self._act(mean)
            self.controller.set_alpha(command.alpha)
            self.controller.queue_kd(command.kd)
            self.active_speed, self.pending_speed = self.pending_speed, mean
            self.step_sum, self.step_count = 0.0, 0
        if stop and self.loop.sim.fallen():
            raise StepFailed("the robot fell before the next section")
        return len(speeds)

    def _short_of_section(self, limit: int) -> tuple[int, bool]:
        """Run compiled to the first tick whose phase is within ``section_margin`` of the
        section, or to whatever ends the run first (a touchdown, a fall, ``limit`` ticks).
        Returns the ticks run and whether the next tick crosses the section: a run whose last
        tick jumped past the section is undone (the MuJoCo state and the controller restored)
        and replayed one tick shorter, the same ticks again, bit for bit."""
        model, data = self.model, self.data
        mujoco.mj_getState(model, data, self._before, self._spec)
        controller, tick = self._controller_state(), self.loop.sim.tick
        speeds, stop = self.loop.advance(limit, self.section_phase - self.section_margin)
        if self.controller.touchdown or self.controller.tau < self.section_phase:
            return self._commit(speeds, stop), False
        mujoco.mj_setState(model, data, self._before, self._spec)
        self.loop.sim.tick = tick
        self._restore_controller(controller)
        return (self._ticks(len(speeds) - 1) if len(speeds) > 1 else 0), True

    def run_to_section(self) -> None:
        """Simulate to the next mid-stance crossing after a touchdown and leave the
        simulator (and the running step sum) at the interpolated crossing. The ticks run
        compiled to the touchdown, then to just short of the section; the last few, the one
        on which the phase crosses among them, run alone, the crossing interpolated between
        the two states around it."""
        model, data, controller = self.model, self.data, self.controller
        before, after = self._before, self._after
        touched = crossing_next = False
        left = self.max_ticks
        while left > 0:
            if not touched:  # no crossing counts before the touchdown: compiled to it
                left -= self._ticks(left)
                touched = controller.touchdown
                continue
            if not crossing_next and controller.tau < self.section_phase - self.section_margin:
                ran, crossing_next = self._short_of_section(left)
                left -= ran
                if ran and (controller.touchdown or left == 0):
                    crossing_next = False
                    continue
            g_before = controller.tau - self.section_phase
            mujoco.mj_getState(model, data, before, self._spec)
            stance_before, sum_before = controller.stance, self.step_sum
            self._ticks(1)
            left -= 1
            crossing_next = False
            g_after = controller.tau - self.section_phase
            if controller.stance == stance_before and g_before < 0.0 <= g_after:
                mujoco.mj_getState(model, data, after, self._spec)
                w = -g_before / (g_after - g_before)
                mujoco.mj_setState(model, data, section_crossing(g_before, g_after, before, after), self._spec)
                mujoco.mj_forward(model, data)
                self.step_sum = (1.0 - w) * sum_before + w * self.step_sum
                return
        raise StepFailed(f"no section crossing within {self.max_ticks} ticks (stalled)")

    # ------------------------------------------------------------------- map
    def __call__(self, x: np.ndarray) -> np.ndarray:
        """One step from section coordinates ``x`` to the next crossing's coordinates."""
        self._apply(np.asarray(x, dtype=float))
        self.run_to_section()
        return self.coordinates()

    def natural_states(self, steps: int) -> np.ndarray:
        """``steps`` consecutive section states of the unperturbed walk (from the current
        state; the capture is then moved to the last of them)."""
        states = []
        for _ in range(steps):
            self.run_to_section()
            states.append(self.coordinates())
        self.capture()
        return np.array(states)

    def perturbation_decay(self, x_star: np.ndarray, delta: np.ndarray, scales: np.ndarray, steps: int,
                           floor: float) -> float | None:
        """Measured per-step contraction: start at ``x_star + delta``, walk ``steps``
        steps unperturbed, fit log|(x_k - x*) / scales| over the steps while it stays
        above ``floor`` (the natural jitter in the same units); the slope's exponential
        is the dominant |lambda| as the walk itself shows it. None if the perturbation
        vanished into the jitter within 3 steps or the walk failed."""
        weights = 1.0 / scales
        try:
            self._apply(x_star + delta)
            distances = []
            for _ in range(steps):
                self.run_to_section()
                distances.append(float(np.linalg.norm((self.coordinates() - x_star) * weights)))
        except StepFailed:
            return None
        keep = []
        for k, d in enumerate(distances):
            if d <= floor:
                break
            keep.append((k, np.log(d)))
        if len(keep) < 3:
            return None
        k, logd = np.array(keep).T
        return float(np.exp(np.polyfit(k, logd, 1)[0]))


def default_scales(feedback: bool, angle: float = 3e-3, rate: float = 3e-2, speed: float = 1e-2) -> np.ndarray:
    """Perturbation scales per coordinate: rad, rad/s and (memory) m/s."""
    scales = [angle] * 5 + [rate] * 5
    return np.array(scales + ([speed] * MEMORY_DIMENSION if feedback else []))


def analyse_stability(policy: Policy, desired_speed: float, feedback: bool, samples: int = 400,
                      natural_steps: int = 12, seed: int = 0, model: ModelOptions = ModelOptions(),
                      decay_steps: int = 30) -> StabilityResult:
    """Poincaré test at one commanded speed: the fixed point is the mean of
    ``natural_steps`` section states of the settled walk (the sampled cycle jitters at
    ~1e-4 rad, so iterating the map does not converge tighter), the Jacobian a
    least-squares central difference over ``samples`` random symmetric perturbations
    (:func:`.poincare.regression_fit`; runs that fall or stall are dropped and counted),
    and, as a cross-check, the measured decay of a perturbation ten times the scales
    along the Jacobian's slowest eigenvector."""
    step = WalkReturnMap(policy, desired_speed, feedback, model)
    natural = step.natural_states(natural_steps)
    x_star = natural.mean(axis=0)
    scales = default_scales(feedback)
    fit = regression_fit(step, x_star, scales, samples, seed=seed, skip=(StepFailed,))
    residual = float(np.linalg.norm(natural[-1] - x_star))
    analysis = PoincareAnalysis(x_star, residual, fit.jacobian)
    jitter = natural.std(axis=0)
    values, vectors = np.linalg.eig(fit.jacobian)
    slowest = np.real(vectors[:, int(np.argmax(np.abs(values)))])
    delta = 10.0 * scales * slowest / np.max(np.abs(slowest / scales) * scales)
    floor = 3.0 * float(np.linalg.norm(jitter / scales))
    decay = step.perturbation_decay(x_star, delta, scales, decay_steps, floor)
    return StabilityResult(analysis, fit, jitter, decay)
