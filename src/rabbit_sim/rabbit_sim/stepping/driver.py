"""The simulator driven by sim_node's stepping rules, without ROS: :class:`SimDriver` takes
the node's events (an initial state, a torque reply, a push, reset and pause requests,
the recorder's progress, the wall-clock timers) and returns the actions they call for, in
order (:class:`State` to publish, :class:`PushApplied`, :class:`Fallen`, :class:`Placed`,
:class:`Markers`, a viewer :class:`Frame`, :class:`Log` lines). ``sim_node`` turns those
into messages and log calls; the tests run it with a fake wall clock and no rclpy.

Modes (``SimSettings.mode``), as docs/architecture.md describes them: ``lockstep`` (one
torque reply per state, :class:`~.rules.Lockstep`), ``paced`` (lockstep held to the wall
clock, :class:`~.rules.Pacer`) and ``realtime`` (1 kHz of wall clock, zero-order hold,
:class:`~.rules.RealtimeClock`, :class:`~.rules.Watchdog`, :class:`~.rules.LatenessMonitor`).

Stamps are ns of sim time; wall times are seconds of ``clock`` (``time.perf_counter``).
"""

from __future__ import annotations

import time
from rabbit_msgs_py.log_lines import LogLine
from dataclasses import dataclass
from typing import Callable

from rabbit_msgs_py import topics
from rabbit_msgs_py.joints import N_ACTUATED
from rabbit_msgs_py.pairing import PairingKey

from rabbit_msgs_py.topics import REPLY_MODES

from ..physics import compiled
from .markers import RobotShapes, marker_period_ticks
from .settings import SimSettings
from ..physics.simulation import Simulator, TorqueDelay
from .rules import (
    FOLLOW_PATIENCE,
    RECORDER_LAG,
    RECORDER_RESEND,
    REFUSED_NAMED,
    REPLY_GRACE,
    SILENCE_WARNING_AFTER,
    Admit,
    ControllerPairing,
    LatenessMonitor,
    Lockstep,
    Pacer,
    RealtimeClock,
    RecorderGate,
    Reply,
    TickStatistics,
    TorquePublishers,
    Watchdog,
    WatchdogEvent,
    silence_cause,
)


# ------------------------------------------------------------------ actions
@dataclass(frozen=True)
class State:
    """Publish the state at ``stamp`` (ns): positions (m, rad), velocities (m/s, rad/s) of
    the 7 joints and the applied actuator efforts (N m), world frame for the base; then
    tell :meth:`SimDriver.sent` (the latency of its reply counts from then)."""

    stamp: int
    qpos: list[float]
    qvel: list[float]
    effort: list[float]
    track_latency: bool = False


@dataclass(frozen=True)
class PushApplied:
    """The push on the torso from ``stamp`` on: (fx N, fz N, ty N m), world frame; zeros: none."""

    stamp: int
    wrench: tuple[float, float, float]


@dataclass(frozen=True)
class Fallen:
    value: bool


@dataclass(frozen=True)
class Placed:
    """The robot was placed (start or reset) for the ``count``-th time."""

    count: int


@dataclass(frozen=True)
class Markers:
    """Publish the robot's shapes (``RobotShapes.shapes``) at ``stamp``."""

    stamp: int
    shapes: object


@dataclass(frozen=True)
class Frame:
    """Sync the viewer window (``force``: now, whatever its frame rate)."""

    force: bool = False


Log = LogLine
"""A log line for the node (:class:`rabbit_msgs_py.log_lines.LogLine`)."""


Action = State | PushApplied | Fallen | Placed | Markers | Frame | Log


def seconds_to_ns(seconds: float) -> int:
    """Seconds (a parameter's value) as the integer ns of a stamp."""
    return int(round(seconds * 1e9))


class SimDriver:
    """The simulation and its stepping rules for one ``SimSettings``; see the module
    docstring. Not thread-safe: the node calls it under one lock."""

    def __init__(self, settings: SimSettings, sim: Simulator, clock: Callable[[], float] = time.perf_counter,
                 shapes: bool = True, namespace: str = "/", key: PairingKey | None = None) -> None:
        """``key``: the pairing key resolved from ``settings.pairing_key`` (the node resolves it:
        :func:`rabbit_msgs_py.pairing.resolve_key`); None: no key."""
        compiled.warm()  # the compiled rules loaded now, not on the first step (half a second in real time)
        self.settings, self.sim, self.clock = settings, sim, clock
        self.namespace = namespace  # the node's: log lines name topics in full (_topic)
        mode = settings.mode
        self.by_replies = mode in REPLY_MODES
        self.initial_state: tuple[list[float], list[float]] | None = None
        self.started = False
        self.paused = settings.start_paused
        self.halted = False  # fell, reached stop_time, or (realtime) fell too far behind
        self.fallen = False
        self.halt_reason = ""
        self.placements = 0
        self.pushes_rejected = 0
        self.achieved_rtf: float | None = None  # paced: over the last 5 s
        sim.schedule_pushes(settings.pushes)  # the Simulator applies them, as on the fast path
        self.stats = TickStatistics()
        self.lockstep = Lockstep(settings.resend_timeout, clock)
        self.pacer = Pacer(settings.rtf, clock=clock) if mode == "paced" else None
        self.pace_pending = False  # paced: the newest state waits for its wall time
        self.recorder = RecorderGate(settings.wait_for_recorder and self.by_replies, RECORDER_LAG,
                                     sim.tick_ns)
        self.pairing = ControllerPairing(key)  # every mode: torques from one controller
        self.watchdog = Watchdog(settings.watchdog_timeout, settings.damping)
        self.lateness = LatenessMonitor(settings.max_late_fraction, clock=clock)
        self.realtime = RealtimeClock(sim.timestep, clock=clock)
        self._delay = TorqueDelay(settings.delay_ticks) if settings.delay_ticks else None  # the fast path's rule
        self._latest_torques = [0.0] * N_ACTUATED  # realtime: zero-order hold on the newest torque
        self._latest_torque_wall = -1.0
        self._held_ticks = 0
        self.published_stamp: int | None = None  # ns, the newest state sent
        self._recorder_resent = -RECORDER_RESEND
        self._recorder_waits_since: float | None = None  # wall s the simulation began to wait for the recorder
        self._recorder_ignored = False  # a followed recorder did not keep up: none followed until all have left
        self._unpaired: str | None = None  # no key: the last controller refused since a reply was accepted
        self._refused: dict[str, None] = {}  # sources refused so far (the first REFUSED_NAMED), each logged apart
        self._shapes = RobotShapes(sim.model) if shapes else None
        self._marker_period = marker_period_ticks(settings.markers_rate, sim.timestep) if shapes else 0
        self.markers_wanted: Callable[[], bool] = lambda: True  # the node: is anyone subscribed to the markers?
        self._out: list[Action] = []

    # ---------------------------------------------------------------- events
    def _topic(self, name: str) -> str:
        """A stack topic's full name in the node's namespace (for log lines)."""
        return topics.resolve(name, self.namespace)

    def on_initial_state(self, qpos: list[float], qvel: list[float]) -> list[Action]:
        """The newest state to start and reset from; the first one places the robot."""
        self._out = []
        self.initial_state = (qpos, qvel)
        if not self.started:
            self._place()
            self._log("info", f"robot placed in the initial state (hip at {qvel[0]:.2f} m/s); simulation "
                              + ("paused" if self.paused else "running"))
        return self._out

    def on_torques(self, stamp: int, frame_id: str, torques: list[float], now: float) -> list[Action]:
        """A torque reply to the state stamped ``stamp`` (ns) from ``frame_id`` (the
        controller instance, signed with the stack's key where there is one; ``now``: when
        it arrived, wall s)."""
        self._out = []
        self.stats.torque_received(now, stamp)
        if not self.by_replies:
            if not self._admitted(frame_id, stamp, torques):
                return self._out
            self._latest_torques = torques
            self._latest_torque_wall = now
            if self.started and not (self.paused or self.halted) and self.realtime.overdue() >= 0.0:
                self._run_due_ticks()  # the tick waited for this reply
            return self._out
        if self.lockstep.answers_due(stamp) and self._admitted(frame_id, stamp, torques):
            self._act(self.lockstep.on_reply(torques, self._must_hold()), torques)
        return self._out

    def on_release_controller(self) -> tuple[bool, str, list[Action]]:
        """``/sim/release_controller``: (done, message, actions); see :class:`ControllerPairing`."""
        self._out = []
        done, message = self.pairing.release()
        if done:
            self._log("warning", f"{message} (t = {self.sim.time:.3f} s)")
        return done, message, self._out

    def sent(self, state: State) -> None:
        """The node published ``state`` (now: where its reply's latency starts)."""
        self.stats.state_sent(self.clock(), state.stamp, state.track_latency)

    def on_malformed_torques(self) -> None:
        self.stats.torques_rejected += 1

    def on_push(self, fx: float, fz: float, ty: float, ignored: bool = False) -> list[Action]:
        """A push on the torso (N, N, N m; ``ignored``: components the planar model drops)."""
        self._out = []
        values = (fx, fz, ty)
        if not all(abs(v) <= self.settings.max_push_force for v in values):
            self.pushes_rejected += 1
            self._log("error", f"ignoring push {tuple(round(v, 6) for v in values)}: components must be finite and "
                               f"within +-{self.settings.max_push_force} N")
            return self._out
        if ignored:
            self._log("warning", "push: the model is planar; force.y, torque.x and torque.z are ignored")
        self.sim.push(fx, self.settings.push_duration, fz, ty)
        self._push_applied()
        self._log("info", f"push at t = {self.sim.time:.3f} s: fx = {fx:.1f} N, fz = {fz:.1f} N, "
                          f"ty = {ty:.1f} N m for {self.settings.push_duration:.3f} s")
        return self._out

    def on_reset(self, initial_state_topic: str) -> tuple[bool, str, list[Action]]:
        """``/sim/reset``: (success, message, actions)."""
        self._out = []
        if self.initial_state is None:
            return False, f"no initial state received on {initial_state_topic} yet", self._out
        if self.lockstep.request_reset():
            return True, "reset at the next tick", self._out  # the reply to the state in flight comes first
        self._place()
        message = "robot back in the initial state at t = 0 s"
        self._log("info", message)
        return True, message, self._out

    def on_pause(self, paused: bool) -> tuple[str, list[Action]]:
        """``/sim/pause``: (message, actions)."""
        self._out = []
        self.paused = paused
        if not paused and self.pacer is not None:
            self.pacer.restart()  # pace from the next step: no rush to make up the pause
        if not paused and self.by_replies:
            self._resume()
        message = "paused" if paused else "running"
        self._log("info", f"simulation {message} at t = {self.sim.time:.3f} s")
        return message, self._out

    def on_recorded(self, stamp: int) -> list[Action]:
        """The recorder has written the state at ``stamp`` (ns; negative: a recorder announced
        itself). Lockstep/paced: a recorder that turns up is followed (:class:`RecorderGate`)."""
        self._out = []
        if not self.by_replies or self._recorder_ignored:
            return self._out
        if self.recorder.report(stamp):
            self._log("info", f"a recorder turned up at t = {self.sim.time:.3f} s: the simulation steps at its pace "
                              "while it records, so it loses nothing")
        if not self.paused and self.lockstep.held_torques is not None:
            self._resume()
        return self._out

    def supervise(self, torque_publishers: Callable[[], TorquePublishers],
                  recorders: Callable[[], int] = lambda: 1) -> list[Action]:
        """Lockstep/paced, a 20 Hz wall-clock timer: the achieved real-time factor (paced), the recorder's first state, a followed
        recorder that left (``recorders()``: publishers of its reports), and the state sent
        again when its reply is overdue (``torque_publishers()``: who publishes torques,
        asked only then, for the log line that names the cause)."""
        self._out = []
        now = self.clock()
        if self.pacer is not None:
            self._report_pace()
        if self.recorder.following or self._recorder_ignored:
            if recorders() == 0:
                if self.recorder.following:
                    self._log("info", f"the recorder left at t = {self.sim.time:.3f} s: the simulation steps freely "
                                      "again")
                self._let_recorder_go(ignore=False)
            elif (self.recorder.following and self._recorder_waits_since is not None
                  and now - self._recorder_waits_since >= FOLLOW_PATIENCE):
                self._log("warning", f"the recorder on {self._topic(topics.RECORDED_UNTIL)} has not kept up for "
                                     f"{FOLLOW_PATIENCE:g} s ({self.recorder.behind(self.published_stamp)}): stepping "
                                     "freely, and following no recorder until every publisher of it has left (a "
                                     "recording started by hand may lose states from here; run_stack's wait)")
                self._let_recorder_go(ignore=True)
        if not self.started or self.pace_pending:
            return self._out
        if not self.paused and self.recorder.holds(self.published_stamp):
            if self._recorder_waits_since is None:
                self._recorder_waits_since = now
            if now - self._recorder_resent >= RECORDER_RESEND:
                self._recorder_resent = now
                self._send_state()  # the recorder may never have had it (connected late)
            if now - self._recorder_waits_since >= SILENCE_WARNING_AFTER:  # (a start takes a moment)
                self._log("warning", f"lockstep: waiting for the recorder: "
                                     f"{self.recorder.behind(self.published_stamp)}", 5.0, "recorder")
            return self._out
        self._recorder_waits_since = None
        waited = self.lockstep.resend_due(self.paused)
        if waited is None:
            return self._out
        if waited >= SILENCE_WARNING_AFTER:  # (by then a stopped or killed controller's liveliness has lapsed)
            why = silence_cause(torque_publishers(), self.pairing.controller, self._topic(topics.JOINT_TORQUES),
                                f"{self._topic(topics.ALPHA)} and {self._topic(topics.KD)}", self._unpaired,
                                self._topic(topics.RELEASE_CONTROLLER_SERVICE))
            # before any controller has answered this is a start (nodes started by hand come up
            # seconds apart): said, not warned; once one has, silence is a fault
            level = "warning" if self.pairing.controller is not None else "info"
            self._log(level, f"lockstep: no torque for the state at t = {self.sim.time:.3f} s after {waited:.1f} "
                             f"s; re-sending it every {self.settings.resend_timeout:g} s ({why})", 5.0, "resend")
        self._send_state()
        return self._out

    def _let_recorder_go(self, ignore: bool) -> None:
        """Stop following the recorder (``ignore``: and any other until every publisher of its
        reports has left: a recorder that stalls, or a node that only announces one, cannot
        hold the simulation for good)."""
        self.recorder.let_go()
        self._recorder_ignored = ignore
        self._recorder_waits_since = None
        if not self.paused and self.lockstep.held_torques is not None:
            self._resume()

    @property
    def pace_wait(self) -> float | None:
        """Paced: wall s until the state that waits for its wall time is due (<= 0: now);
        None while none waits (the node arms its one-shot timer only then)."""
        return self.pacer.wait(self.sim.time) if self.pace_pending else None

    def paced_wake(self) -> list[Action]:
        """Paced, the node's one-shot timer at :attr:`pace_wait`: send the state that waits
        for its wall time, if it is due."""
        self._out = []
        if self.pace_pending and self.pacer.wait(self.sim.time) <= 0.0:
            self.pace_pending = False
            self._send_next_state()
        return self._out

    def _report_pace(self) -> None:
        """Paced, from the 20 Hz supervision: the achieved real-time factor, once per window."""
        achieved = self.pacer.achieved(self.sim.time)
        if achieved is not None and self.started and not (self.paused or self.halted):
            self.achieved_rtf = achieved
            slow = achieved < 0.95 * self.settings.rtf
            self._log("info", f"paced: real-time factor {achieved:.2f} (target {self.settings.rtf:g}) at "
                              f"t = {self.sim.time:.1f} s"
                              + ("; this machine cannot keep up, the simulation runs slower" if slow else ""))

    def realtime_wake(self) -> list[Action]:
        """Realtime, a 1 ms timer: the ticks now due by the wall clock, zero-order hold."""
        self._out = []
        if not self.started or self.paused or self.halted:
            self.stats.forget()
            self.realtime.restart()
        elif not (self.stats.awaiting_reply and self.realtime.overdue() < REPLY_GRACE):
            self._run_due_ticks()  # (else the reply is on its way, queued behind this timer: it runs the tick)
        return self._out

    # ---------------------------------------------------------------- status
    @property
    def controller(self) -> str | None:
        """Id of the controller whose torques are applied (None before the first reply)."""
        return self.pairing.controller

    def statistics(self) -> dict:
        """Counters for scripts and benchmarks (JSON-ready: None, never NaN)."""
        extra = {"damped_ticks": self.watchdog.damped_ticks, "resends": self.lockstep.resends,
                 "skipped_ticks": self.realtime.skipped, "halt_reason": self.halt_reason or None}
        summary = self.stats.summary(self.sim.time, extra)
        if self.pacer is not None:  # sim s stepped per wall s, first tick to last (pauses included)
            rate = summary["tick_rate_hz"]
            summary["achieved_rtf"] = rate * self.sim.timestep if rate is not None else None
            summary["paced_fell_behind"] = self.pacer.behind_count
        return summary

    # ------------------------------------------------------------- internals
    def _log(self, level: str, text: str, throttle: float = 0.0, key: str = "") -> None:
        self._out.append(Log(level, text, throttle, key))

    def _act(self, reply: Reply, torques: list[float]) -> None:
        """Carry out what :class:`Lockstep` made of the paired controller's reply."""
        if reply is Reply.STEP:
            self._advance(torques)
        elif reply is Reply.RESET:
            self._place()
            self._log("info", "robot back in the initial state at t = 0 s")
        # HOLD: kept until the step may run

    def _admitted(self, frame_id: str, stamp: int, torques: list[float]) -> bool:
        """Is the reply from the paired controller? A newly paired one is logged, any other
        refused and logged (:class:`ControllerPairing`)."""
        verdict, source = self.pairing.admit(frame_id, stamp, torques)
        if verdict is Admit.REFUSE:
            self.stats.torques_rejected += 1
            if self.pairing.key is None:
                self._unpaired = source
            why = ("it is not signed with this stack's pairing key" if self.pairing.key is not None
                   else f"this simulator takes them from {self.pairing.controller} only ('ros2 service call "
                        f"{self._topic(topics.RELEASE_CONTROLLER_SERVICE)} std_srvs/srv/Trigger' pairs the next "
                        "to answer)")
            if self.pairing.key is not None and source and source == self.pairing.controller:
                who = f"a node that copied the paired controller's id {source}"  # the real one signs
            else:
                who = f"a node naming itself {source}" if source else "an unnamed publisher"
            self._log("error", f"ignoring torques from {who} on {self._topic(topics.JOINT_TORQUES)}: {why}", 5.0,
                      self._refusal_key(source))
            return False
        self._unpaired = None
        if verdict is Admit.PAIR:
            self._log("info", f"paired with controller {source} at t = {self.sim.time:.3f} s"
                              + (" (signed with this stack's pairing key)" if self.pairing.key is not None else ""))
        return True

    def _refusal_key(self, source: str) -> str:
        """The throttle key of a refusal line: one per source for the first
        :data:`REFUSED_NAMED` sources (a rogue's lines never hide another node's, the real
        controller's with a wrong key included), one for all later ones (a node inventing a
        name per reply cannot flood the log)."""
        if source in self._refused or len(self._refused) < REFUSED_NAMED:
            self._refused[source] = None
            return f"refused {source}"
        return "refused"

    def _must_hold(self) -> bool:
        """Lockstep/paced: the physics may not step now (paused, or a recorder lags)."""
        return self.paused or self.recorder.holds(self.published_stamp)

    def _resume(self) -> None:
        """Lockstep/paced: step on torques held while the step could not run, or send the
        due state again for a controller (or recorder) that came late."""
        if self._must_hold():
            return
        held = self.lockstep.take_held()
        if held is not None:
            self._advance(held)
        elif self.lockstep.awaiting_reply:
            self._send_state()

    def _place(self) -> None:
        pushing = any(self.sim.push_wrench)
        self.sim.reset(*self.initial_state)
        self.placements += 1
        self._out.append(Placed(self.placements))  # before the placed state goes out
        if pushing:  # the reset removed it
            self._push_applied()
        self.started, self.halted, self.halt_reason, self.pace_pending = True, False, "", False
        self.lockstep.restart()
        if self._delay is not None:
            self._delay.clear()
        if self.pacer is not None:
            self.pacer.restart()
        self.stats.forget()
        self._latest_torque_wall = -1.0
        if self.fallen:
            self.fallen = False
            self._out.append(Fallen(False))
        if self._marker_period:
            self._markers()  # a viewer shows the robot where it stands, before it walks
        if self.settings.viewer:
            self._out.append(Frame(force=True))
        if self.by_replies:
            self._send_next_state()

    def _advance(self, torques: list[float]) -> None:
        """Lockstep/paced: apply one reply, step, send the next state (its reply is then due,
        unless the physics halted); paced, the state waits for its wall time."""
        if self.pacer is not None:
            self.pacer.begin(self.sim.time)  # the first step after a placement or resume: pace from here
        self._step(torques)
        if self.pacer is not None and not self.halted and self.pacer.wait(self.sim.time) > 0.0:
            self.pace_pending = True  # paced_wake sends it
            return
        self._send_next_state()

    def _send_next_state(self) -> None:
        stamp = self._send_state()
        if not self.halted:
            self.lockstep.published(stamp)

    def _send_state(self, track_latency: bool = False) -> int:
        data = self.sim.data
        stamp = self.sim.stamp
        self._out.append(State(stamp, data.qpos.tolist(), data.qvel.tolist(), data.qfrc_actuator.tolist(),
                               track_latency))
        self.published_stamp = stamp
        return stamp

    def _push_applied(self) -> None:
        self._out.append(PushApplied(self.sim.stamp, tuple(self.sim.push_wrench)))

    def _markers(self) -> None:
        if self.markers_wanted():
            self._out.append(Markers(self.sim.stamp, self._shapes.shapes(self.sim.data)))

    def _step(self, torques: list[float]) -> None:
        sim = self.sim
        if self._delay is not None:
            torques = self._delay(torques)
        sim.step(torques)
        self.stats.tick(self.clock())
        if self._marker_period and sim.tick % self._marker_period == 0:
            self._markers()
        if self.settings.viewer:
            self._out.append(Frame())
        if sim.push_changed:  # a scheduled push started, or a push ended
            self._push_applied()
            fx, fz, ty = sim.push_wrench
            if fx or fz or ty:
                self._log("info", f"scheduled push at t = {sim.time:.3f} s: fx = {fx:.1f} N")
        if sim.fallen():
            self.halted = self.fallen = True
            self._out.append(Fallen(True))
            qpos = sim.data.qpos
            self._log("warning", f"RABBIT fell at t = {sim.time:.3f} s (hip height {qpos[1]:.3f} m, torso pitch "
                                 f"{qpos[2]:.3f} rad); physics halted, call {self._topic(topics.RESET_SERVICE)} to "
                                 "start again")
        elif self.settings.stop_time and sim.stamp >= seconds_to_ns(self.settings.stop_time):
            self.halted = True
            self._log("info", f"stop_time {self.settings.stop_time:.3f} s reached; physics halted")

    def _run_due_ticks(self) -> None:
        """Realtime: the ticks due now by the wall clock."""
        for _ in range(self.realtime.due()):
            if self._latest_torque_wall < 0.0:
                # hold the initial state (re-published every 10 ms) until the controller answers
                self._held_ticks += 1
                if self._held_ticks % 10 == 1:
                    self._send_state()
                continue
            self._held_ticks = 0
            self._realtime_tick()
            if self.halted:
                break
        self._report_lateness()

    def _report_lateness(self) -> None:
        """Once a second: say when the control loop fell behind in that second; halt the
        physics when it fell too far behind to go on."""
        late = self.lateness.check(self.stats, self.realtime.skipped)
        if late is None:
            return
        what = (f"{late.late} of {late.ticks} ticks ran on a stale torque and {late.skipped} were skipped in the last "
                f"second, worst delay {late.worst_ms:.1f} ms")
        if not late.stop:
            self._log("warning", f"realtime: the control loop fell behind at t = {self.sim.time:.2f} s: {what}")
            return
        self.halted = True
        self.halt_reason = f"the control loop could not keep up with the wall clock ({what})"
        self._log("error", f"realtime: physics halted at t = {self.sim.time:.2f} s: {self.halt_reason}; walking on "
                           "stale torques would make RABBIT fall. On a slow or busy machine use mode:=paced (never "
                           "steps without its torque)")

    def _realtime_tick(self) -> None:
        now = self.clock()
        self.stats.realtime_tick_due(now)
        rates = self.sim.data.qvel[3:3 + N_ACTUATED].tolist()
        torques, event = self.watchdog.torques(self._latest_torques, self._latest_torque_wall, now, rates)
        if event is WatchdogEvent.RESUMED:
            self._log("info", f"torque commands resumed at t = {self.sim.time:.3f} s; damping off")
        elif event is WatchdogEvent.TRIPPED:
            self._log("warning", f"watchdog: no torque for {self.watchdog.timeout * 1e3:.0f} ms at "
                                 f"t = {self.sim.time:.3f} s; applying damping ({self.watchdog.damping:.0f} N m s/rad) "
                                 "until commands resume")
        self._step(torques)
        self._send_state(track_latency=True)
