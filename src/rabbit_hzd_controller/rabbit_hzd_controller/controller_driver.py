"""The controller node's rules, without ROS: which gait answers which state. :class:`ControllerDriver`
takes ``hzd_controller_node``'s events (a gait part, the policy's gait timing parsed by
``rabbit_msgs_py.decision_ticks.parse_gait_timing``, a reset count,
a state, the decision timer) and returns what to do, in order (:class:`Answer` a state,
:class:`Repeat` the last reply, :class:`Log` a line). The node parses and validates the
messages, then publishes what comes back; the tests drive it with no rclpy, as
``rabbit_sim.stepping.SimDriver`` is driven for the simulator.

* The first complete gait (alpha and Kd) becomes the controller's start gait; a state that
  comes before it (or, with ``decision_sync`` following the policy, before its timing) waits
  and is answered once it is in.
* Later gaits: queued to the next touchdown (``next_step``), or applied on arrival, blended in
  (``at_once``); which, the policy's ``/hzd/gait_timing`` says unless fixed.
* ``decision_sync`` with the policy deciding every N ticks: the reply to a state the policy
  decides on (:class:`~rabbit_msgs_py.decision_ticks.PeriodicDecisions`) waits until that
  decision's alpha and Kd are in (one of each per due state, in order; a rejected part
  counts) and they apply to that state, as in the ROS-free loop. None within
  ``decision_timeout`` s (wall): the state is answered with the gait in force, and gaits
  apply on arrival until the policy's next alpha and Kd are in.
* A reset (a new count on ``/sim/resets``, or a stamp older than the last) restarts the
  controller on the gait in force and answers the next state even if it repeats the last
  one; a state identical to the last one answered (a lockstep re-send) gets the same reply
  again (:class:`Repeat`).
* A controller that joins mid-run (restarted by the stack) answers its first state with the
  gait in force: a decision on that state went to the old instance.
* A policy that goes silent (no gait part for :data:`SILENT_DECISIONS` of its decision periods
  of sim time, or :data:`SILENT_PER_STEP` s when it decides once per step, and for
  :data:`SILENT_WALL` s of wall time: a policy in a process of its own may lag the simulation
  without being gone) is logged once, with since when and the gait the robot walks on; its
  return is logged too.

Stamps are ns of sim time; ``clock`` is wall time (s, ``time.monotonic``).
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass
from typing import Callable, Sequence, Union

from rabbit_msgs_py.decision_ticks import GAIT_TIMINGS, TICK_NS, PeriodicDecisions

from . import law
from .controller import ControllerConfig, HZDController, Leg, infer_stance

@dataclass(frozen=True)
class Answer:
    """Publish the torques (N m, the four actuated joints) answering the state at ``stamp``;
    ``touchdown``: the stance switched on it (``/hzd/step`` first), ``stance`` the new stance
    leg, ``tau``/``tau_rate`` the phase and its rate (1/s) on it."""

    stamp: int
    torques: list[float]
    touchdown: bool
    stance: Leg
    tau: float
    tau_rate: float


@dataclass(frozen=True)
class Repeat:
    """The state at ``stamp`` was sent again: publish the last reply again, unchanged."""

    stamp: int


SILENT_DECISIONS = 5
"""Decision periods without a gait part after which the policy counts as silent."""
SILENT_PER_STEP = 2.0
"""s of sim time without a gait part after which a policy deciding once per step counts as
silent (a step lasts at most 0.75 s; the stall rule's 2 s)."""
SILENT_WALL = 1.0
"""s of wall time without a gait part, besides the sim time above, before the policy counts as
silent: a live policy behind the simulation (hand-started nodes run without decision_sync)
still sends a gait every few ms of wall time."""


@dataclass(frozen=True)
class Log:
    level: str  # "info" | "warning"
    text: str


Action = Union[Answer, Repeat, Log]
State = tuple[int, list[float], list[float]]  # stamp (ns), q (7: m, rad), dq (7: m/s, rad/s)


SIM_SILENT_WALL = 1.0
"""wall s without any state (a new one or one sent again) after which the simulator counts as
silent: a live simulator sends the state whose reply it waits for again every
``resend_timeout`` (0.2 s by default) in lockstep and paced mode, and a new one every tick in
realtime, so only a simulator that stopped, died or was paused goes this long without one."""

FIRST_STATE_WAIT = 5.0
"""wall s after the start without any state after which the controller says so, once (a
simulator not started, in another namespace or domain, or one whose states do not reach it)."""

SIM_MODE_WAIT = 2.0
"""wall s: a controller following the simulator's ``/sim/mode`` answers no state before it
comes, for at most this long after the first state (a simulator that never says)."""


class ControllerDriver:
    """See the module docstring. ``gait_timing``: ``"policy"`` (follow ``/hzd/gait_timing``;
    ``next_step`` until it says) or one of :data:`GAIT_TIMINGS`."""

    def __init__(self, config: ControllerConfig, gait_timing: str = "policy", decision_sync: bool = False,
                 decision_timeout: float = 2.0, clock: Callable[[], float] = time.monotonic,
                 mode_known: bool = True) -> None:
        """``mode_known`` False: ``decision_sync`` follows the simulator (:meth:`on_sim_mode`),
        and no state is answered before it says how it steps, or :data:`SIM_MODE_WAIT` wall s
        have passed since the first state (then ``decision_sync`` stays as given)."""
        if gait_timing != "policy" and gait_timing not in GAIT_TIMINGS:
            raise ValueError(f"gait_timing must be policy or one of {GAIT_TIMINGS}, got {gait_timing!r}")
        law.warm()  # the compiled law loaded now, not on the first state (a real-time tick's worth and more)
        self.config = config
        self.follow_policy_timing = gait_timing == "policy"
        self.gait_timing = "next_step" if self.follow_policy_timing else gait_timing
        self.decision_sync, self.decision_timeout, self.clock = decision_sync, decision_timeout, clock
        self.controller: HZDController | None = None
        self.alpha: list[float] | None = None  # the last good gait received
        self.kd: float | None = None
        self._last: tuple[int, list[float], list[float]] | None = None  # the state last answered
        self._waiting: State | None = None  # arrived before the gait was complete
        self._dropped: State | None = None  # the last state taken for a re-send
        self._resets: int | None = None  # the last count seen on /sim/resets
        self._restart = False  # a reset was announced: restart on the next state
        # decision_sync: the due states (None: not holding), the gait parts not yet taken
        # (None for a rejected one), the state waiting for its decision (and since when)
        self._due: PeriodicDecisions | None = None
        self._gaits: dict[str, deque] = {"alpha": deque(), "kd": deque()}
        self._held: tuple[State, float] | None = None
        self._timing_unknown = decision_sync and self.follow_policy_timing  # the first state waits for it
        self._timing_seen = False  # the policy's /hzd/gait_timing came
        self._mode_known = mode_known
        self._mode_wait: float | None = None  # wall s (clock) of the first state held for the mode
        self._sync_paused = False  # a decision timed out: gaits apply on arrival until both come again
        self._period = 0  # the policy's decision period (ticks; 0: once per step)
        self._gait_at: int | None = None  # stamp (ns) of the newest state when a gait part last came
        self._gait_wall = 0.0  # wall s (clock) when a gait part last came
        self._silent_since: int | None = None  # the policy is silent (logged): since this stamp
        self.states_received = 0
        self.replies_repeated = 0
        self.decisions_waited = 0  # due states answered with their decision
        self.decisions_timed_out = 0
        self.silences = 0  # times the policy was found silent (logged)
        self._state_wall: float | None = None  # wall s (clock) of the last state (sent again or not)
        self._state_stamp = 0  # ns: that state's stamp
        self._sim_silent_since: float | None = None  # the simulator is silent (logged): since this wall s
        self.simulator_silences = 0  # times the simulator was found silent (logged)
        self._started_wall = clock()  # wall s (clock): no state before FIRST_STATE_WAIT past this is said
        self._said_no_state = False
        self._out: list[Action] = []

    @property
    def last_stamp(self) -> int:
        """The stamp (ns) of the state last answered, -1 before any (or after a reset)."""
        return self._last[0] if self._last is not None else -1

    @property
    def decision_period(self) -> int:
        """The decision period followed (ticks; 0: once per step, or not known)."""
        return self._period

    @property
    def last_state(self) -> tuple[list[float], list[float]] | None:
        """(q, dq) of the state last answered."""
        return (self._last[1], self._last[2]) if self._last is not None else None

    @property
    def missing(self) -> list[str]:
        """What a state waits for before it can be answered: ``alpha``, ``kd``, ``gait_timing``."""
        return ([name for name, part in (("alpha", self.alpha), ("kd", self.kd)) if part is None]
                + (["gait_timing"] if self._timing_unknown else []) + ([] if self._mode_known else ["sim_mode"]))

    # ---------------------------------------------------------------- events
    def on_gait_part(self, part: str, value) -> list[Action]:
        """A gait part that arrived, ``part`` ``alpha`` (24 rad, validated) or ``kd``
        (N m s/rad); ``value`` None: it was rejected (it still counts as a decision's part)."""
        self._out = []
        if self._silent_since is not None:
            now = max(self.last_stamp, 0)
            silence = (f"after {(now - self._silent_since) / 1e9:.3f} s without one" if now >= self._silent_since
                       else "the first since the simulation was placed again")  # a reset: sim time restarted
            self._log("info", f"the policy is back: a gait on /hzd/{part} at t = {now / 1e9:.3f} s, {silence}")
            self._silent_since = None
        self._gait_at = max(self.last_stamp, 0)
        self._gait_wall = self.clock()
        if value is not None:
            setattr(self, part, list(value) if part == "alpha" else value)
        self._take(part, value)
        if value is not None:
            self._answer_waiting()
        return self._out

    def _timing_words(self, timing: str) -> str:
        """How gaits apply under ``timing`` and this controller's configuration, for the log."""
        if timing != "at_once":
            return "at the next touchdown"
        c = self.config
        if c.within_step_blend <= 0.0:
            return "when they arrive, at once (no blend" + (", no queue)" if c.within_step_until >= 1.0 else
                                                            f"; from {c.within_step_until:g} of phase queued for the touchdown)")
        return (f"when they arrive, blended in over {c.within_step_blend:g} of phase; from {c.within_step_until:g} "
                "of phase queued for the touchdown")

    def on_gait_timing(self, timing: str, period: int) -> list[Action]:
        """The policy's ``/hzd/gait_timing``, parsed (:func:`parse_gait_timing`); ignored
        unless following the policy."""
        self._out = []
        if not self.follow_policy_timing:
            return self._out
        if timing != self.gait_timing:
            self._log("info", f"gaits apply {self._timing_words(timing)}")
        self.gait_timing = timing
        self._period = period
        self._timing_unknown = False
        self._timing_seen = True
        due = PeriodicDecisions(period, TICK_NS) if period and self.decision_sync else None
        if due is not None and self.last_stamp >= 0:
            due.join(self.last_stamp)  # mid-run: the policy's clock has followed since the placement
        if (due is None) != (self._due is None) or (due is not None and due.period != self._due.period):
            self._due = due
            self._release_held("the policy's timing changed")
        self._answer_waiting()
        return self._out

    def on_sim_mode(self, holds: bool) -> list[Action]:
        """The simulator says whether it waits for each reply (lockstep, paced: ``holds``):
        ``decision_sync`` follows it (the node calls this only when it was not given)."""
        self._out = []
        self._mode_known = True
        if holds != self.decision_sync:
            self.decision_sync = holds
            if self._timing_seen:
                self._out = self.on_gait_timing(self.gait_timing, self._period)
            else:
                self._timing_unknown = holds and self.follow_policy_timing
        self._answer_waiting()
        return self._out

    def on_resets(self, count: int) -> list[Action]:
        """A count on ``/sim/resets`` (placements of the robot)."""
        self._out = []
        first = self._resets is None
        if count == self._resets:
            return self._out
        self._resets = count
        if first:
            return self._out  # the count in force when this node started: nothing to restart
        self._restart = True
        if self._gait_at is not None:
            self._gait_at = 0  # the placed state's stamps start again from 0
        self._forget_gaits()
        self._held = None  # the placed state comes next; its answer is due, not this one's
        self._forget_last_state()
        return self._out

    def on_state(self, stamp: int, q: list[float], dq: list[float]) -> list[Action]:
        """A state (stamp ns; q, dq: the 7 joints)."""
        self._out = []
        now = self.clock()
        if self._sim_silent_since is not None:
            self._log("info", f"the simulator is back: a state at t = {stamp / 1e9:.3f} s after "
                              f"{now - self._sim_silent_since:.1f} s of wall time without one")
            self._sim_silent_since = None
        self._state_wall, self._state_stamp = now, stamp
        self._check_policy(stamp)
        self._state(stamp, q, dq)
        return self._out

    def _check_policy(self, stamp: int) -> None:
        """Log once when the policy has sent no gait part for longer than it may."""
        if self._gait_at is None or self._silent_since is not None or stamp < self._gait_at:
            return
        limit = SILENT_DECISIONS * self._period * TICK_NS if self._period else int(SILENT_PER_STEP * 1e9)
        if stamp - self._gait_at > limit and self.clock() - self._gait_wall > SILENT_WALL:
            self._silent_since = self._gait_at
            self.silences += 1
            every = f"every {self._period} ms" if self._period else "once per step"
            self._log("warning", f"the policy is silent: no gait since t = {self._gait_at / 1e9:.3f} s (it decides "
                                 f"{every}); walking on the last gait it sent (Kd {self.kd:.1f} N m s/rad, alpha "
                                 f"{', '.join(f'{a:.3f}' for a in (self.alpha or [])[:4])}, ...)")

    def check_held(self) -> list[Action]:
        """Timer: no state at all :data:`FIRST_STATE_WAIT` s after the start (said once); a
        simulator that sent no state for :data:`SIM_SILENT_WALL` s (named, once per
        silence; while it lasts no decision is waited for, as none is waited on); a due
        decision that did not come within ``decision_timeout`` s; a simulator that did not say
        how it steps within :data:`SIM_MODE_WAIT` s of its first state."""
        self._out = []
        if (self._state_wall is None and not self._said_no_state
                and self.clock() - self._started_wall > FIRST_STATE_WAIT):
            self._said_no_state = True
            self._log("info", f"no state on the joint states yet, {FIRST_STATE_WAIT:g} s after the start "
                              f"({'a gait is in' if not self.missing else 'waiting for ' + ', '.join(self.missing)}): "
                              "is sim_node running in this namespace and domain?")
        if (self._state_wall is not None and self._sim_silent_since is None
                and self.clock() - self._state_wall > SIM_SILENT_WALL):
            self._sim_silent_since = self._state_wall
            self.simulator_silences += 1
            self._log("warning", f"the simulator is silent: no state on the joint states for {SIM_SILENT_WALL:g} s "
                                 f"of wall time (the last at t = {self._state_stamp / 1e9:.3f} s): sim_node "
                                 "stopped, died or was paused")
        if self._sim_silent_since is not None:
            return self._out
        if not self._mode_known and self._mode_wait is not None and self.clock() - self._mode_wait > SIM_MODE_WAIT:
            self._mode_known = True
            self._log("warning", f"the simulator did not say how it steps (/sim/mode) within {SIM_MODE_WAIT:g} s: "
                                 f"decision_sync {'on' if self.decision_sync else 'off'}, as given")
            self._answer_waiting()
        if self._held is not None and self.clock() - self._held[1] > self.decision_timeout:
            self.decisions_timed_out += 1
            self._sync_paused = True
            self._release_held(f"no decision from the policy within {self.decision_timeout:g} s")
        return self._out

    # ------------------------------------------------------------- internals
    def _log(self, level: str, text: str) -> None:
        self._out.append(Log(level, text))

    def _state(self, stamp: int, q: list[float], dq: list[float]) -> None:
        self.states_received += 1
        if self._held is not None and stamp == self._held[0][0]:
            return  # re-sent while it waits for its decision: answered once it is in
        if self._last is not None and stamp == self._last[0] and (q, dq) == (self._last[1], self._last[2]):
            self._dropped = (stamp, q, dq)
            self._out.append(Repeat(stamp))  # a re-send: the same reply again
            self.replies_repeated += 1
            return
        if self.missing:
            self._waiting = (stamp, q, dq)
            if not self._mode_known and self._mode_wait is None:
                self._mode_wait = self.clock()
            return
        controller = self.controller
        if controller is None or self._restart or stamp < self.last_stamp:
            stance = infer_stance(q, self.config.geometry)
            if controller is None:
                controller = self.controller = HZDController(self.alpha, self.kd, self.config, stance)
                if self._due is not None and stamp > 0:
                    # joined mid-run (the stack restarted this controller): the gait in force is the
                    # policy's newest decision (transient local); a decision on this state went to the
                    # old instance, so it is answered at once instead of waiting out decision_timeout
                    self._due.join(stamp)
            else:
                controller.reset(self.alpha, self.kd, stance)
                self._log("info", "simulation reset: controller restarted on the gait")
            self._restart = False
        self._dropped = None
        if self._due is not None and self._due.due(stamp) and self._syncing:
            # (a newer state while one waits: its reply was given up, the older one is dropped)
            self._held = ((stamp, q, dq), self.clock())
            self._answer_held()
            return
        self._answer(stamp, q, dq)

    @property
    def _syncing(self) -> bool:
        """Holding due states for their decision now."""
        return self._due is not None and not self._sync_paused and self.gait_timing == "at_once"

    def _take(self, part: str, value) -> None:
        """A gait part (None: rejected) that arrived: kept for the next due state while
        holding for decisions, else applied as ``gait_timing`` says (the first gait, before
        any state, becomes the controller's start gait instead)."""
        if self.controller is None:
            return
        if self._syncing:
            self._gaits[part].append(value)
            self._answer_held()
            return
        if self._sync_paused:
            self._gaits[part].append(value)  # counted: sync resumes once alpha and Kd came again
            if self._gaits["alpha"] and self._gaits["kd"]:
                self._sync_paused = False
                self._forget_gaits()
        if value is not None:
            self._apply(part, value, self.gait_timing == "at_once")

    def _apply(self, part: str, value, at_once: bool) -> None:
        if part == "alpha":
            self.controller.apply_now(tuple(value)) if at_once else self.controller.set_alpha(value)
        else:
            self.controller.set_kd(value) if at_once else self.controller.queue_kd(value)

    def _forget_gaits(self) -> None:
        for parts in self._gaits.values():
            parts.clear()

    def _forget_last_state(self) -> None:
        """Answer the next state even if it repeats the last one answered; a state dropped
        as a re-send before the event that asked for this is answered now."""
        self._last = None
        if self._dropped is not None:
            state, self._dropped = self._dropped, None
            self._state(*state)

    def _answer_waiting(self) -> None:
        """Answer the state that arrived before the first complete gait, if any."""
        if self._waiting is not None and not self.missing:
            state, self._waiting = self._waiting, None
            self._state(*state)

    def _answer_held(self) -> None:
        """Answer the state waiting for its decision once that decision's alpha and Kd are in."""
        if self._held is None or not (self._gaits["alpha"] and self._gaits["kd"]):
            return
        (stamp, q, dq), _since = self._held
        self._held = None
        alpha, kd = self._gaits["alpha"].popleft(), self._gaits["kd"].popleft()
        if alpha is not None:
            self.controller.apply_now(tuple(alpha), kd)  # as the ROS-free loop applies a decision
        elif kd is not None:
            self._apply("kd", kd, at_once=True)
        self.decisions_waited += 1
        self._answer(stamp, q, dq)

    def _release_held(self, why: str) -> None:
        """Answer a held state with the gait in force (sync paused until the policy's next gait)."""
        if self._held is None:
            return
        (stamp, q, dq), _since = self._held
        self._held = None
        self._forget_gaits()
        self._log("warning", f"{why}: answering t = {stamp / 1e9:.3f} s with the gait in force; gaits apply "
                             "on arrival until the policy's next one")
        self._answer(stamp, q, dq)

    def _answer(self, stamp: int, q: Sequence[float], dq: Sequence[float]) -> None:
        controller = self.controller
        torques = controller.compute(q, dq)
        self._last = (stamp, q, dq)
        self._out.append(Answer(stamp, torques, controller.touchdown, controller.stance, controller.tau,
                                controller.tau_rate))
