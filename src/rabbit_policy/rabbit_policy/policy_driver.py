"""The ROS-free core of ``policy_node`` (:mod:`.policy_node`): events in, actions out (as
:class:`rabbit_sim.stepping.SimDriver` is sim_node's and
:class:`rabbit_hzd_controller.controller_driver.ControllerDriver` the controller node's).

:class:`PolicyDriver` holds the policy, the commanded speed (clamped into
[``min_speed``, ``max_speed``] m/s, a non-finite one rejected), the speed schedule, the
:class:`~.decision_clock.DecisionClock` (when to decide and over which samples, stamps in ns)
and, for a policy that reads the body state inside the step, the
:class:`~.body.BodyStateBuffer` its decisions wait on. Each event method returns the
actions to carry out, in order: :class:`Gait` (publish alpha and Kd, and the initial state on
that gait), :class:`Scheduled` (a scheduled command, published on ``/cmd_speed`` for the
record) and :class:`Log`. The node turns messages into events and actions into messages.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from rabbit_hzd_controller.gait_state import state_on_gait
from rabbit_msgs_py.decision_ticks import TICK_NS
from rabbit_msgs_py.log_lines import LogLine
from rabbit_msgs_py.rejections import RejectionLog
from rabbit_policy.experiment.scenario import parse_schedule, validate_schedule
from rabbit_policy.runtime import exact_sum, fixed_order
from rabbit_policy.runtime.body import BodyStateBuffer
from rabbit_policy.runtime.speed_command import clamp_message, clamp_speed
from rabbit_policy.runtime.decision_clock import DecisionClock
from rabbit_policy.runtime.gait_command import GaitCommand, Policy
from rabbit_policy.runtime.policies import DEFAULT_DECISION_WINDOW, decision_period, first_command, reset_policy
from rabbit_policy.runtime.speed_schedule import SpeedSchedule
from rabbit_policy.runtime.speed_window import Observation

SCHEDULE_SOURCE = "speed_schedule"
"""Where a scheduled command comes from, in log lines."""


@dataclass(frozen=True)
class Gait:
    """Publish ``command`` (alpha rad, Kd N m s/rad) and, if not None, the initial state on
    it (``qpos``, ``qvel``: the simulator's start and reset state)."""

    command: GaitCommand
    initial_state: tuple[np.ndarray, np.ndarray] | None
    error: str = ""  # why there is no initial state
    same_initial_state: bool = False  # the one published with the last gait: not sent again


@dataclass(frozen=True)
class Scheduled:
    """A scheduled command (m/s), published on ``/cmd_speed`` for recordings and plots."""

    speed: float


Log = LogLine
"""A log line for the node (:class:`rabbit_msgs_py.log_lines.LogLine`)."""


Action = Gait | Scheduled | Log


@dataclass(frozen=True)
class PolicySettings:
    """``policy_node``'s settings besides the policy (speeds m/s, windows in 1 ms ticks):
    the command range, the command before the first one (and the initial state's hip
    speed), the averaging windows and the speed schedule (``'T:V,...'``, '' = none)."""

    min_speed: float
    max_speed: float
    initial_speed: float
    window: int
    decision_window: int
    speed_schedule: str = ""
    phase_topic: str = "/hzd/phase"  # named in the line when a decision's phase never comes
    command_rate: float = 0.0  # m/s per s of sim time a live command is followed at (0: at once)


def speed_schedule(text: str, initial_speed: float) -> SpeedSchedule | None:
    """The ``speed_schedule`` parameter: None for ''; else its changes, checked as walk.py's
    schedule is (``ValueError`` with one line)."""
    if not text:
        return None
    try:
        changes = parse_schedule(text)
        validate_schedule(((0.0, initial_speed), *changes))
    except ValueError as exc:
        raise ValueError(f"speed_schedule: {exc}") from None
    return SpeedSchedule(changes)


def decision_window(policy: Policy, settings: PolicySettings) -> int:
    """The moving-average window (ticks) of a policy deciding every N ticks: the node's
    ``decision_window`` if given (> 0), else the policy's own (its spec's ``window_ticks``, as
    the ROS-free loop takes it)."""
    return settings.decision_window or int(getattr(policy, "decision_window", DEFAULT_DECISION_WINDOW))


SIM_SILENT_WALL = 1.0
"""wall s without a sample of the simulation (a hip velocity) after which the policy says so:
the simulator stopped, died or was paused, or no controller answers it (lockstep holds the
simulation for its controller's reply)."""


class PolicyDriver:
    """``policy`` deciding on the events of a walk; see the module docstring. ``ValueError``
    (one line) for settings it cannot run with."""

    def __init__(self, policy: Policy, settings: PolicySettings) -> None:
        self.target: float | None = None  # a live command the desired speed is still moving to (command_rate)
        self.set_range(settings.min_speed, settings.max_speed, settings.initial_speed)
        if not math.isfinite(settings.initial_speed) or not self.min_speed <= settings.initial_speed <= self.max_speed:
            raise ValueError(f"initial_speed must be a finite number in [{self.min_speed}, {self.max_speed}], "
                             f"got {settings.initial_speed}")
        if settings.window < 1:
            raise ValueError(f"window must be >= 1 tick, got {settings.window}")
        if settings.decision_window < 0:
            raise ValueError(f"decision_window must be >= 0 ticks (0: the policy's own), got {settings.decision_window}")
        self.policy = policy
        self.settings = settings
        self.decision_period = decision_period(policy)
        self.needs_body = bool(getattr(policy, "needs_body", False))
        if self.needs_body and not self.decision_period:
            raise ValueError("this policy reads the body state inside the step and decides every N ticks; "
                             "decision_period 0 (once per step) cannot run it")
        self.clock = DecisionClock(self.decision_period, decision_window(policy, settings) if self.decision_period
                                   else settings.window, tick=TICK_NS)
        exact_sum.warm()  # the window's compiled sum loaded now, not on the first decision
        fixed_order.warm()  # and the network's forward pass
        self.initial_speed = self.desired_speed = settings.initial_speed
        self.schedule = speed_schedule(settings.speed_schedule, self.initial_speed)
        self.body: BodyStateBuffer | None = BodyStateBuffer(TICK_NS) if self.needs_body else None
        self.awaiting: deque[tuple[int, Observation]] = deque()  # due decisions waiting for their body state
        self.rejections = RejectionLog()  # bad input: counted, logged at most once a second per kind
        self.decisions = self.rejected_commands = self.decisions_given_up = 0
        self.last_observation: Observation | None = None
        self._initial: tuple[tuple, float, Gait] | None = None  # (alpha, initial speed, the gait that carried it)
        self.placements = 0
        self._echoes: list[float] = []  # scheduled commands published on /cmd_speed, not yet heard back
        if not (math.isfinite(settings.command_rate) and settings.command_rate >= 0.0):
            raise ValueError(f"command_rate must be a finite number >= 0 m/s per s, got {settings.command_rate}")
        self.command_rate = settings.command_rate
        self._ramp_stamp: int | None = None  # ns: the newest sample the ramp has followed to
        self.samples = 0  # hip velocities taken
        self._watched: tuple[int, float] | None = None  # (samples, wall s) when the count last moved
        self._silent = False
        self.simulation_silences = 0  # times the simulation was found silent (logged)

    # ----------------------------------------------------------------- events
    def start(self) -> list[Action]:
        """The first gait: the start, on the command."""
        return [self._gait(first_command(self.policy, self.desired_speed))]

    def set_range(self, low: float, high: float, command: float | None = None) -> None:
        """A new command range (m/s, each end validated by the caller): the command in force
        (``command`` if given) is clamped into it; ``ValueError`` if ``low`` > ``high``."""
        if not low <= high:
            raise ValueError(f"min_speed ({low}) must not be above max_speed ({high})")
        self.min_speed, self.max_speed = low, high
        self.desired_speed = min(max(self.desired_speed if command is None else command, low), high)
        if self.target is not None:
            self.target = min(max(self.target, low), high)

    def on_command(self, value: float, source: str) -> list[Action]:
        """A commanded speed (m/s) from ``source`` (a topic's name, in log lines)."""
        return self._command(value, source)

    def on_cmd_speed(self, value: float, source: str) -> list[Action]:
        """``/cmd_speed``: a command, unless it is the echo of a scheduled one this node published."""
        if self._echoes and value == self._echoes[0]:
            self._echoes.pop(0)
            return []
        return self._command(value, source)

    def on_placed(self, count: int) -> None:
        """The robot was placed for the ``count``-th time: from the second on (a reset), a
        policy with memory starts afresh and the schedule starts over, as each walk of the
        ROS-free loop does."""
        if count > 1 and count != self.placements:
            reset_policy(self.policy)
            self.awaiting.clear()  # decisions of the walk before the placement
            self._ramp_stamp = None  # sim time starts again
            if self.schedule is not None:
                self.schedule.restart()
                self.desired_speed = self.initial_speed
        self.placements = count

    def on_hip_velocity(self, stamp: int, speed: float) -> list[Action]:
        """A state's hip velocity (m/s, world x) stamped ``stamp`` ns: a scheduled change due
        then, the sample, and the decisions that fall due; ``ValueError`` for a speed that is not
        finite (nothing taken)."""
        if not math.isfinite(speed):
            raise ValueError(f"hip velocity {speed} is not a finite number (m/s)")
        self.samples += 1
        actions = self._follow_schedule(stamp)
        self._follow_ramp(stamp)
        due = self.clock.sample(stamp, speed, self.desired_speed)  # ValueError: a stamp it cannot take
        if self.body is None:
            return actions + [self._decide(observation) for observation in due]
        if self.awaiting and stamp < self.awaiting[-1][0]:
            self.awaiting.clear()  # placed again: those were the last walk's
        self.awaiting.extend((stamp, observation) for observation in due)
        return actions + self._decide_awaiting()

    def on_body_state(self, stamp: int, qpos: np.ndarray, qvel: np.ndarray) -> list[Action]:
        """A body-state policy: a state (``JOINT_NAMES`` order) stamped ``stamp`` ns."""
        self.body.add_state(stamp, qpos, qvel)
        return self._decide_awaiting()

    def on_phase(self, stamp: int, tau: float, rate: float) -> list[Action]:
        """A body-state policy: the controller's phase on the state stamped ``stamp`` ns."""
        self.body.add_phase(stamp, tau, rate)
        return self._decide_awaiting()

    def on_step(self, stamp: int) -> list[Action]:
        """A touchdown on the state stamped ``stamp`` ns (the loop decides on the one after).
        The schedule is followed only at samples: a touchdown may come before the states up
        to it (a batch), and those states keep the command they had in the loop."""
        return [self._decide(o) for o in self.clock.switch(stamp, self.desired_speed)]

    def check_simulation(self, now: float) -> list[Action]:
        """Timer (``now``: wall s, monotonic; call a few times a second): one warning when no
        sample has come for :data:`SIM_SILENT_WALL` s since the first, one line when they come
        again."""
        if self.samples == 0:
            return []
        if self._watched is None or self._watched[0] != self.samples:
            back = self._silent
            self._watched, self._silent = (self.samples, now), False
            return [Log("info", "the simulation is back: its samples come again")] if back else []
        if self._silent or now - self._watched[1] <= SIM_SILENT_WALL:
            return []
        self._silent = True
        self.simulation_silences += 1
        last = self.last_sample_stamp
        return [Log("warning", f"the simulation is silent: no state for {SIM_SILENT_WALL:g} s of wall time"
                               + (f" (the last at t = {last / 1e9:.3f} s)" if last is not None else "")
                               + ": the simulator stopped, died or was paused, or no controller answers it")]

    @property
    def last_sample_stamp(self) -> int | None:
        """ns: the stamp of the newest sample taken (None before any)."""
        return self.clock.newest

    def flush(self) -> list[Action]:
        """The tails of throttled rejection bursts (call about once a second)."""
        return [Log("warning", line) for line in self.rejections.flush()]

    # ---------------------------------------------------------------- helpers
    def _follow_schedule(self, stamp: int) -> list[Action]:
        speed = self.schedule.due(stamp) if self.schedule is not None else None
        if speed is None:
            return []
        self._echoes.append(speed)
        return [Log("info", f"t = {stamp / 1e9:.3f} s: scheduled command {speed:.2f} m/s"),
                *self._command(speed, SCHEDULE_SOURCE), Scheduled(speed)]

    def _command(self, value: float, source: str) -> list[Action]:
        """Clamped into range, rejected if not finite (each kind of line at most once a second)."""
        actions = []
        try:
            speed = clamp_speed(value, self.min_speed, self.max_speed)
        except ValueError as exc:
            self.rejected_commands += 1
            line = self.rejections.line(f"reject {source}", lambda exc=exc: f"rejected {source}: {exc}; keeping "
                                                                            f"{self.desired_speed:.2f} m/s")
            return [Log("error", line)] if line is not None else []
        if speed != value:
            line = self.rejections.line(f"clamp {source}", lambda: clamp_message(value, self.min_speed,
                                                                                 self.max_speed, speed, source))
            actions += [Log("warning", line)] if line is not None else []
        if speed != (self.target if self.target is not None else self.desired_speed) and source != SCHEDULE_SOURCE:
            line = self.rejections.line("command", f"commanded speed {speed:.2f} m/s")  # (scheduled: with its time)
            actions += [Log("info", line)] if line is not None else []
        if source == SCHEDULE_SOURCE or not self.command_rate or self._ramp_stamp is None:
            self.desired_speed, self.target = speed, None  # the schedule (the fast path's), or before the walk
        else:
            self.target = speed  # followed at command_rate from the next sample (_follow_ramp)
        return actions

    def _follow_ramp(self, stamp: int) -> None:
        """The desired speed moves toward a live command at ``command_rate`` m/s per s of sim
        time (nav2's velocity smoother's rule: no sequence of valid commands makes it jump)."""
        last, self._ramp_stamp = self._ramp_stamp, stamp
        if self.target is None or last is None or stamp <= last:
            return
        step = self.command_rate * (stamp - last) / 1e9
        gap = self.target - self.desired_speed
        if abs(gap) <= step:
            self.desired_speed, self.target = self.target, None
        else:
            self.desired_speed += step if gap > 0 else -step

    def _decide_awaiting(self) -> list[Action]:
        """Decide, in order, the due decisions whose body state is complete; one whose state
        or phase never comes (newer states are in) is given up, logged: the gait in force stays."""
        actions = []
        while self.awaiting:
            stamp, observation = self.awaiting[0]
            body = self.body.body_at(stamp)
            if body is None and not self.body.expired(stamp):
                break
            self.awaiting.popleft()
            if body is None:
                self.decisions_given_up += 1
                actions.append(Log("error", f"no body state for the decision at t = {stamp / 1e9:.3f} s (is the "
                                            f"controller publishing {self.settings.phase_topic}?); keeping the gait "
                                            "in force", throttle=2.0, key="no body state"))
                continue
            actions.append(self._decide(replace(observation, body=body)))
        return actions

    def _decide(self, observation: Observation) -> Gait:
        self.last_observation = observation
        return self._gait(self.policy.act(observation))

    def _gait(self, command: GaitCommand) -> Gait:
        """The gait to publish; its initial state computed only when alpha or the initial
        speed changed since the last gait (``same_initial_state``: nothing new to send)."""
        self.decisions += 1
        key = (tuple(command.alpha), self.initial_speed)
        if self._initial is not None and self._initial[:2] == key:
            last = self._initial[2]
            return Gait(command, last.initial_state, last.error, same_initial_state=True)
        try:
            gait = Gait(command, state_on_gait(command.alpha, self.initial_speed))
        except (ValueError, ZeroDivisionError) as exc:
            gait = Gait(command, None, str(exc))
        self._initial = (*key, gait)
        return gait
