"""The one ROS-free closed loop: the RABBIT simulator, the HZD controller and (optionally) a
gait policy, stepped together at 1 kHz. Every experiment runs it: ``scripts/walk.py``,
the Gymnasium environment and training, the gait optimizer, the Poincaré analysis, the
acceptance checks and the evaluation. The node stack runs the same pieces over topics
(``sim_node`` steps the same :class:`~rabbit_sim.physics.simulation.Simulator`, which applies the
same push schedule; ``hzd_controller_node`` runs the same :class:`HZDController`;
``policy_node`` the same policy on the same :class:`SpeedWindow` observation), which is
why a lockstep run reproduces this loop bit for bit.

One tick (:meth:`ClosedLoop.tick`):

1. the controller turns the state into four torques (delayed by the scenario's
   ``torque_delay`` if any) and the simulator steps once, starting and ending pushes;
2. the commanded speed follows the schedule; the hip speed joins the policy's speed window;
3. the stop rules: a fall, or no touchdown for ``stall_after`` s (a stall; with
   ``roll_back_after`` also the hip rolling back behind its stance foot that long);
4. at a touchdown the policy sees the window's observation over the step just ended and
   its gait (alpha, Kd) is queued for the next touchdown — as ``policy_node`` answers
   ``/hzd/step``. Without a policy the gait in force stays (a fixed gait; the learning
   environment sets the gait itself between touchdowns). A policy deciding every N ticks
   (:class:`~rabbit_policy.runtime.policies.PeriodicPolicy`) instead sees the moving
   average over its window every N ticks, and its gait applies at once, blended in.

The robot starts at phase 0 of the starting gait, left stance, its hip moving at the
scenario's first commanded speed (or ``start_speed``), as ``sim_node`` places it.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable, Sequence

import mujoco
import numpy as np

from rabbit_hzd_controller.controller import ControllerConfig, HZDController, Leg
from rabbit_hzd_controller.gait import Gait
from rabbit_hzd_controller.gait_state import state_on_gait
from rabbit_msgs_py.pushes import Push
from rabbit_policy.experiment import ticks
from rabbit_policy.experiment.result import Decision, Touchdown, WalkResult
from rabbit_policy.experiment.scenario import Scenario, on_tick_grid, whole_ticks
from rabbit_policy.runtime import exact_sum, fixed_order
from rabbit_policy.runtime.body import body_state
from rabbit_policy.runtime.policies import GaitCommand, Policy, controller_settings, first_command, reset_policy
from rabbit_policy.runtime.policies import decision_period as policy_decision_period
from rabbit_policy.runtime.decision_clock import DecisionClock
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.speed_schedule import SpeedSchedule, stamp_of
from rabbit_policy.runtime.speed_window import Observation
from rabbit_sim.physics.model import ModelOptions, load_model
from rabbit_sim.physics.simulation import Simulator, StopRules, TorqueDelay

CHUNK = 4096
"""Most ticks one compiled call runs (the size of its buffers)."""

Observer = Callable[["ClosedLoop", Sequence[float]], None]
"""Called after every tick with the loop and the torques applied (N m)."""


class ClosedLoop:
    """Simulator + HZD controller (+ gait policy) for one scenario; see the module docstring.

    ``start``: the gait in force at t = 0 (default: the policy's :func:`first_command`).
    ``controller``: the controller's configuration (None: ``ControllerConfig()``), with the
    settings the policy needs (:func:`controller_settings`) over it; ``kp``
    overrides its proportional gain (None: keep it). ``model``:
    a compiled model to reuse (must match ``scenario.model``). ``observer``: called every
    tick. ``record_state``: keep per-tick ``qpos``/``qvel``/stance. ``observe_speed``:
    keep the speed window without a policy (the learning environment), observed as a policy
    deciding every ``decision_period`` ticks (0: once per step) would see it (with a policy,
    the policy's own ``decision_period`` is used). ``start_tick``: the simulator's tick count
    at the placement (sim time ``start_tick`` ms; the scenario's times are absolute).
    """

    def __init__(self, scenario: Scenario, policy: Policy | None = None, start: GaitCommand | None = None,
                 *, start_speed: float | None = None, kp: float | None = None,
                 controller: ControllerConfig | None = None,
                 model: mujoco.MjModel | None = None, observer: Observer | None = None,
                 record_state: bool = False, observe_speed: bool = False,
                 decision_period: int = 0, decide_outside: bool = False, start_tick: int = 0) -> None:
        if decide_outside and (policy is not None or not observe_speed or not decision_period):
            raise ValueError("decide_outside is for a loop without a policy, observing every N > 0 ticks")
        reset_policy(policy)  # a policy with memory starts each walk afresh
        if start is None:
            if policy is None:
                raise ValueError("a closed loop needs a policy or a starting gait")
            start = first_command(policy, scenario.initial_speed)
        self.scenario = scenario
        self.policy = policy
        self.model = model if model is not None else load_model(scenario.model)
        self.sim = Simulator(self.model, scenario.rules.fall)
        self.data = self.sim.data
        config = replace(controller or ControllerConfig(), **controller_settings(policy))
        if kp is not None:
            config = replace(config, kp=kp)
        self.controller = HZDController(start.alpha, start.kd, config, Leg.LEFT)
        speed = scenario.initial_speed if start_speed is None else start_speed
        self.sim.reset(*state_on_gait(start.alpha, speed, config.geometry))
        self.sim.tick = start_tick
        self.sim.schedule_pushes(scenario.pushes)
        self._phase_pushes = list(scenario.phase_pushes)  # placed in time at a touchdown (_touchdown)
        self.placed_pushes: list = []  # the phase pushes as placed (rabbit_msgs_py.pushes.Push)
        self.observer = observer
        self.record_state = record_state
        # decide_outside: the decisions fall due as for a policy deciding every N ticks, each kept
        # in `pending` (with the body state) for the caller to decide on (the learning env)
        self._deciding = policy is not None or decide_outside
        self.decide_outside = decide_outside
        self.pending: Observation | None = None
        self._period = policy_decision_period(policy) if policy is not None else decision_period
        window = policy.decision_window if (policy is not None and self._period) else scenario.window
        # when the policy decides and what it sees: the rule policy_node runs too (stamps: sim
        # time in ticks, a sample being the state after a step)
        self.clock = DecisionClock(self._period, window) if (policy is not None or observe_speed) else None
        self.window = None if self.clock is None else self.clock.window
        self._stall_after = scenario.rules.stall_after
        self.schedule = SpeedSchedule(scenario.schedule[1:])  # policy_node's rule (speed_schedule)
        self._next_change = self._change_check()
        self.desired_speed = scenario.initial_speed
        dt = self.model.opt.timestep
        delay = int(round(scenario.torque_delay / dt))
        self._delay = TorqueDelay(delay) if delay else None
        # the compiled ticks' state (ticks.run_ticks): time, the fall limits, the early stall rule
        fall = scenario.rules.fall
        self._feet = (self.model.site("left_foot").id, self.model.site("right_foot").id)
        self._state = np.zeros(ticks.LOOP_STATE_SIZE)
        self._state[[ticks.TICK_NS, ticks.TIMESTEP, ticks.MIN_HEIGHT, ticks.MAX_HEIGHT, ticks.MAX_PITCH, ticks.ROLL_BACK_TICKS,
                     ticks.LEFT_FOOT, ticks.RIGHT_FOOT]] = (
            self.sim.tick_ns, dt, fall.min_hip_height, fall.max_hip_height, fall.max_abs_pitch,
            int(round(scenario.rules.roll_back_after / dt)), *self._feet)
        self._state[ticks.SECTION] = np.inf  # no section stop (advance's section_phase)
        self._no_delay = (np.zeros((0, 4)), np.zeros(1))
        self._buffers = (np.zeros(CHUNK), np.zeros(CHUNK), np.zeros(CHUNK))  # times, hip x, hip speed
        self._applied = np.zeros(4)
        self._bind()
        # what happened
        self.ticks = 0
        self.start_time = self.sim.time  # every time on the ns grid of the stack's stamps (whole ticks)
        self.start_x = float(self.data.qpos[0])
        self._time_chunks: list[np.ndarray] = []  # sim time (s) and hip x (m) after each tick, per compiled run
        self._x_chunks: list[np.ndarray] = []
        self._qpos_rows: list[np.ndarray] = []
        self._qvel_rows: list[np.ndarray] = []
        self._stance: list[int] = []
        self.touchdowns: list[Touchdown] = []
        self.decisions: list[Decision] = []
        self.fell = self.stalled = False
        self.fall_time: float | None = None
        self.stall_time: float | None = None
        self._last_touchdown_time = self.start_time

    def _bind(self) -> None:
        """Keep views of the MuJoCo data's fields (MjData makes a new one on every access);
        again after the data is copied (:func:`~rabbit_policy.evaluation.ceiling.clone_loop`)."""
        self.data = self.sim.data
        self._qpos, self._qvel = self.data.qpos, self.data.qvel
        self._ctrl, self._site_xpos = self.data.ctrl, self.data.site_xpos
        self.sim.bind()

    # ------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        """Simulation time (s): the whole ticks since the placement (:attr:`Simulator.time`)."""
        return self.sim.time

    @property
    def failed(self) -> bool:
        return self.fell or self.stalled

    def set_command(self, speed: float) -> None:
        """Command ``speed`` m/s from now on (the schedule's later changes still apply)."""
        self.desired_speed = float(speed)

    def observation(self, moving: bool = False) -> Observation:
        """What the policy would see now (:meth:`DecisionClock.observe`): over the last whole
        step (touchdown to touchdown; since the start before the first), or with ``moving``
        (a loop deciding every N ticks) the moving average over the last step's duration."""
        if self.clock is None:
            raise RuntimeError("this loop keeps no speed window (no policy, observe_speed=False)")
        if moving != bool(self._period):
            raise ValueError("observation(moving) must match the decision period the loop was built with")
        return self.clock.observe(self.desired_speed)

    def set_gait(self, command: GaitCommand) -> bool:
        """Queue a gait for the next touchdown; False (and the gait in force stays) if the
        controller rejects it."""
        try:
            self.controller.set_alpha(command.alpha)
            self.controller.queue_kd(command.kd)
        except ValueError:
            return False
        return True

    def apply_gait(self, command: GaitCommand) -> bool:
        """Apply a gait at once, within the step, blended in (``HZDController.apply_now``);
        False (and the gait in force stays) if the controller rejects it."""
        try:
            self.controller.apply_now(command.alpha, command.kd)
        except ValueError:
            return False
        return True

    def body_state(self) -> tuple[float, ...]:
        """The body state now (:func:`~rabbit_policy.runtime.body.body_state`: torso pitch,
        its rate, the phase, its rate, the hip velocity)."""
        c = self.controller
        return body_state(self._qpos, self._qvel, c.tau, c.tau_rate)

    @property
    def peak_torque(self) -> float:
        """The largest |torque| applied so far (N m)."""
        return float(self._state[ticks.PEAK])

    # ------------------------------------------------------------------- tick
    def tick(self) -> bool:
        """One control tick and physics step (see the module docstring); returns True when
        a stop rule fired this tick (fell or stalled)."""
        return self._advance(1)[1]

    def advance(self, limit: int, section_phase: float = np.inf) -> tuple[np.ndarray, bool]:
        """Up to ``limit`` ticks at once, compiled: to the first thing Python decides (see
        :meth:`_quiet_ticks`), a touchdown, a stop rule, or (``section_phase``) the first tick
        whose phase tau is at or past that phase (the controller's ``tau`` then says so). Returns the hip
        velocity (m/s, world x) after each tick run and whether a stop rule fired (fell or
        stalled)."""
        self._state[ticks.SECTION] = section_phase
        try:
            k, stop = self._advance(limit)
        finally:
            self._state[ticks.SECTION] = np.inf
        return self._buffers[2][:k].copy(), stop

    def _quiet_ticks(self, limit: int) -> int:
        """How many ticks (1 to ``limit``) may run compiled at once: nothing Python decides
        falls strictly inside them (a decision, a command change, a stall by time, a
        recorded state or an observer), only possibly on the last."""
        if limit == 1 or self.observer is not None or self.record_state:
            return 1
        n = min(limit, CHUNK)
        if self.clock is not None and self._deciding:  # nobody decides: the samples only
            due = self.clock.next_due
            if due is not None:
                n = min(n, max(1, due - self.ticks))
        now, dt = self.sim.time, self._state[ticks.TIMESTEP]
        for event in (self._next_change, self._last_touchdown_time + self._stall_after):
            if event != float("inf"):  # the first tick that may reach it can be the last
                n = min(n, max(1, int((event - now) / dt - 1e-6) + 1))
        return n

    def _advance(self, limit: int) -> tuple[int, bool]:
        """Run up to ``limit`` ticks compiled (:func:`.ticks.run_ticks`), then what Python
        decides on the last of them; returns (ticks run, a stop rule fired)."""
        controller, data, sim, state = self.controller, self.data, self.sim, self._state
        times, xs, speeds = self._buffers
        cfg, controller_state, gaits = controller.arrays
        queue, count = (self._delay.queue, self._delay.count) if self._delay is not None else self._no_delay
        state[ticks.TICK] = sim.tick
        k = ticks.run_ticks(self.model._address, data._address, self._qpos, self._qvel, self._ctrl, self._site_xpos,
                            cfg, controller_state, gaits, queue, count, sim.push_state, sim.push_schedule,
                            sim.wrench, state, times, xs, speeds, self._applied, self._quiet_ticks(limit))
        sim.tick += k  # the simulator's count (MuJoCo's own float time is not read)
        self._time_chunks.append(times[:k].copy())  # whole ticks, on the ns grid
        self._x_chunks.append(xs[:k].copy())
        i = self.ticks
        self.ticks = i + k
        t = float(times[k - 1])  # whole ticks: on the ns grid of the stack's stamps (16.132)
        if self.clock is not None and k > 1:  # the samples before the last decide nothing (_quiet_ticks)
            self.clock.add_quiet(range(i + 1, i + k), speeds[:k - 1], self.desired_speed, self._deciding)
        if t >= self._next_change:
            speed = self.schedule.due(stamp_of(t))
            if speed is not None:
                self.desired_speed = speed
            self._next_change = self._change_check()
        if self.record_state:
            self._qpos_rows.append(self._qpos.copy())
            self._qvel_rows.append(self._qvel.copy())
            self._stance.append(int(controller.stance))
        if self.observer is not None:
            self.observer(self, self._applied.tolist())
        if self.clock is not None:
            for observation in self.clock.sample(i + k, float(speeds[k - 1]), self.desired_speed,
                                                 self._deciding):  # every N ticks
                self._decide(observation, t)
        stop = False
        flags = int(state[ticks.STOP])
        if flags & ticks.FELL:
            if not self.fell:
                self.fell, self.fall_time = True, t
            stop = True
        if t - self._last_touchdown_time > self._stall_after or flags & ticks.ROLLED_BACK:
            if not self.stalled:
                self.stalled, self.stall_time = True, t
            stop = True
        if controller.touchdown:
            self._touchdown(i + k - 1, t)
        return k, stop

    def _change_check(self) -> float:
        """Sim time (s) from which the hot path asks the schedule (a little before its next
        change: the schedule's own rule, in ns stamps, decides)."""
        stamp = self.schedule.next_stamp
        return (stamp - 2) * 1e-9 if stamp is not None else float("inf")

    def _touchdown(self, i: int, t: float) -> None:
        data = self.data
        foot = data.site_xpos[self._feet[int(self.controller.stance)]]
        self.touchdowns.append(Touchdown(t, float(foot[0]), float(data.qpos[0])))
        if self._phase_pushes and t >= self._phase_pushes[0].after - 1e-9:
            self._place_phase_pushes(t)
        self._last_touchdown_time = t
        if self.clock is not None:
            for observation in self.clock.switch(i, self.desired_speed):  # once per step
                self._decide(observation, t)

    def _place_phase_pushes(self, t: float) -> None:
        """At a touchdown at ``t`` s: the phase pushes now due start in this step, at their
        phase of it, the step taken to last as long as the one just ended."""
        due = [p for p in self._phase_pushes if t >= p.after - 1e-9]
        self._phase_pushes = self._phase_pushes[len(due):]
        placed = [p.place(t, t - self._last_touchdown_time) for p in due]
        self.sim.add_pushes(placed)
        self.placed_pushes.extend(placed)

    def _decide(self, observation: Observation, t: float) -> None:
        """The policy's decision on ``observation``: the gait for the next step (once per step)
        or applied at once, blended in (every N ticks); nothing without a policy (the
        learning environment decides itself)."""
        if self.decide_outside:
            self.pending = replace(observation, body=self.body_state())
            return
        if self.policy is None:
            return
        if getattr(self.policy, "needs_body", False):
            observation = replace(observation, body=self.body_state())
        command = self.policy.act(observation)
        accepted = self.apply_gait(command) if self._period else self.set_gait(command)
        self.decisions.append(Decision(t, observation.mean_speed, self.desired_speed, command.kd, not accepted))

    # -------------------------------------------------------------------- run
    def run(self, duration: float | None = None, stop_on_fall: bool = True, until_touchdown: bool = False,
            max_ticks: int | None = None, until_decision: bool = False) -> bool:
        """Tick for ``duration`` s of sim time (or ``max_ticks`` ticks); with
        ``until_touchdown`` stop after the next touchdown, with ``until_decision``
        (``decide_outside``) once a decision is ``pending``. Returns True if a stop rule
        ended it (fell or stalled; with ``stop_on_fall`` False the walk goes on)."""
        if duration is not None:
            if not duration > 0:
                raise ValueError(f"duration must be > 0 s, got {duration}")
            n = whole_ticks(duration, self.model.opt.timestep)
        elif max_ticks is not None:
            n = max_ticks
        else:
            raise ValueError("give a duration or max_ticks")
        advance, controller = self._advance, self.controller
        done = 0
        while done < n:
            ticks_run, stop = advance(n - done)
            done += ticks_run
            if stop and stop_on_fall:
                return True
            if until_touchdown and controller.touchdown:
                return False
            if until_decision and self.pending is not None:
                return False
        return False

    def result(self) -> WalkResult:
        """What happened so far."""
        record = self.record_state
        return WalkResult(
            scenario=self.scenario, fell=self.fell, fall_time=self.fall_time, stalled=self.stalled,
            stall_time=self.stall_time, start_time=self.start_time, start_x=self.start_x,
            times=_joined(self._time_chunks),  # whole ticks, on the ns grid, as t in _advance
            hip_x=_joined(self._x_chunks), touchdowns=list(self.touchdowns),
            decisions=list(self.decisions), peak_torque=self.peak_torque,
            qpos=np.array(self._qpos_rows).reshape(-1, self.model.nq) if record else None,
            qvel=np.array(self._qvel_rows).reshape(-1, self.model.nv) if record else None,
            stance=np.array(self._stance, dtype=np.int8) if record else None,
        )


def _joined(chunks: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(chunks) if chunks else np.zeros(0)


def walk(policy: Policy | None, scenario: Scenario, duration: float, *, start: GaitCommand | None = None,
         stop_on_fall: bool = True, record_state: bool = False, observer: Observer | None = None,
         kp: float | None = None, start_speed: float | None = None, controller: ControllerConfig | None = None,
         model: mujoco.MjModel | None = None) -> WalkResult:
    """Walk ``duration`` s of sim time under ``scenario`` with ``policy`` choosing every
    step's gait (or the fixed gait ``start`` when ``policy`` is None); a fall or a stall
    ends the walk unless ``stop_on_fall`` is False."""
    loop = ClosedLoop(scenario, policy, start, start_speed=start_speed, kp=kp, controller=controller, model=model,
                      observer=observer, record_state=record_state)
    loop.run(duration, stop_on_fall=stop_on_fall)
    return replace(loop.result(), planned_duration=on_tick_grid(duration, loop.model.opt.timestep))


def compile_kernels() -> float:
    """Compile (or load from numba's cache) every compiled kernel the loop and the nodes run, by
    walking 30 ms with a torque delay, a push and the early stall rule; returns the wall time
    (s). ``make setup`` and the test session call it, so no process compiles on its own."""
    from time import perf_counter

    start = perf_counter()
    gait = GaitLibrary.load().nearest(1.0)
    scenario = Scenario(schedule=((0.0, gait.speed),), pushes=(Push(0.01, 1.0, 0.005),), torque_delay=0.002,
                        rules=StopRules(roll_back_after=0.5))
    loop = ClosedLoop(scenario, start=GaitCommand(gait.alpha, gait.kd))
    loop.run(max_ticks=30)
    loop.controller.compute(loop.data.qpos, loop.data.qvel)  # the node's path: one tick through the class
    loop.sim.step([0.0] * 4)
    loop.sim.fallen()
    exact_sum.warm()
    fixed_order.warm()
    return perf_counter() - start


def walk_gait(gait: Gait, duration: float, model: ModelOptions = ModelOptions()) -> WalkResult:
    """Walk one fixed gait (its own Kp) at its design speed for ``duration`` s (the gait
    tools' check of a designed gait)."""
    return walk(None, Scenario.constant(gait.speed, model=model), duration, start=GaitCommand(gait.alpha, gait.kd),
                kp=gait.kp)
