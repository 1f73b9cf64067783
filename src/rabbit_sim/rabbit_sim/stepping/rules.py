"""The rules ``sim_node`` steps by, without ROS: lockstep bookkeeping (and its pacing),
realtime pacing, the torque watchdog, recorder flow control and the run statistics.
:class:`~.driver.SimDriver` runs them on the simulator; the node only wires the driver to
topics, services and timers. Every rule here is unit-tested without rclpy.

* :class:`Lockstep`: one torque reply per published state, taken only if it carries the
  stamp of the state due (and :class:`ControllerPairing` admits its controller). A reset or pause requested
  while a reply is due takes effect when that reply arrives; an overdue reply makes the
  state go out again (:meth:`Lockstep.resend_due`).
* :class:`Pacer`: paced mode, lockstep held back to the wall clock times a real-time
  factor; slower when the machine cannot keep up, never stepping without its torque.
* :class:`RecorderGate`: lockstep waits for a recorder that lags (by stamps).
* :class:`RealtimeClock`: one tick per timestep of wall-clock time, run from the thread
  that spins the node (no second thread waiting for the GIL); after a late wake-up it
  catches up by at most ``max_burst`` ticks and skips the rest.
* :class:`Watchdog`: in realtime, torques older than ``timeout`` s are replaced by damping
  ``-damping * joint rate``; it says when it trips. :class:`LatenessMonitor` says once a
  second when the loop fell behind, and when it fell too far behind to go on.
* :class:`ControllerPairing`: torques from the paired controller only, in every mode; the
  controller changes by an explicit act (the stack's key, a service call), never by silence.
* :class:`TickStatistics`: counters, late ticks and state->torque latencies; JSON-ready
  (no NaN) for ``stats_file`` and the benchmarks.

Times here are wall-clock seconds (``time.perf_counter``) unless named sim time.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from enum import Enum
from typing import Callable, Sequence

from rabbit_msgs_py.pairing import PairingKey, source_of


RECORDER_LAG = 4
"""Lockstep with wait_for_recorder: states the recorder may lag behind (its subscriptions
keep 10: with at most 4 outstanding none is ever overwritten)."""
FOLLOW_PATIENCE = 5.0
"""s (wall): a recorder the simulation follows without ``wait_for_recorder`` (one started by
hand) that keeps it waiting this long is let go: a stalled recorder, or a node that only
announces one, must not hold the robot for good. run_stack's recordings (``wait_for_recorder``)
wait as long as they need; their supervisor fails a recorder that stops."""
RECORDER_RESEND = 0.05
"""s (wall): while the recorder lacks the state it waits for, the state goes out again this
often (a recorder that connected late, or a report lost)."""
SILENCE_WARNING_AFTER = 2.0
"""s (wall): lockstep says why no torque comes once the due state has waited this long (twice
the controller's liveliness lease, so a stopped or killed one is named as such); the state
goes out again every ``resend_timeout`` meanwhile."""
REFUSED_NAMED = 8
"""Sources of refused torque replies whose log lines are throttled apart (5 s each): one
node's refusals never hide another's; the sources after these share one throttle."""
REPLY_GRACE = 0.0006
"""s: a realtime tick whose reply is still on its way waits this long for it (the reply's
callback then runs the tick) before stepping on the previous torque."""



class Reply(Enum):
    """What to do with the paired controller's reply to the due state, in lockstep."""

    RESET = "reset"  # a reset was requested while the reply was due: reset now
    HOLD = "hold"  # paused, or a recorder lags: keep the torques until the simulation may step
    STEP = "step"  # apply them, step, publish the next state


class Lockstep:
    """Lockstep bookkeeping (see the module docstring): one reply applied per published
    state, and only a reply that carries the stamp of the state now due (whose controller
    :class:`ControllerPairing` then checks). ``clock``: wall time (s); stamps: ns of sim time."""

    def __init__(self, resend_timeout: float, clock: Callable[[], float] = time.perf_counter) -> None:
        self.resend_timeout, self.clock = resend_timeout, clock
        self.due: int | None = None  # stamp of the state whose reply is due
        self.reset_requested = False
        self.held_torques: list[float] | None = None
        self.last_publish = 0.0
        self.resends = 0

    @property
    def awaiting_reply(self) -> bool:
        return self.due is not None

    def published(self, stamp: int) -> None:
        """The state stamped ``stamp`` (ns) went out: its reply is due."""
        self.due = stamp
        self.last_publish = self.clock()

    def restart(self) -> None:
        """The simulation was (re)placed: nothing is due, nothing is held."""
        self.due = None
        self.reset_requested = False
        self.held_torques = None

    def answers_due(self, stamp: int) -> bool:
        """Does a reply stamped ``stamp`` answer the state now due? (Else it is a late
        duplicate, a stale or a made-up stamp: ignored.)"""
        return self.due is not None and stamp == self.due

    def on_reply(self, torques: list[float], hold: bool) -> Reply:
        """Take the paired controller's reply to the due state; the caller then resets, holds
        or steps. ``hold``: the simulation may not step now (paused, a recorder lags)."""
        self.due = None
        if self.reset_requested:
            self.reset_requested = False
            return Reply.RESET
        if hold:
            self.held_torques = torques
            return Reply.HOLD
        return Reply.STEP

    def request_reset(self) -> bool:
        """A reset was asked for; True if it must wait for the reply now due."""
        if self.due is not None:
            self.reset_requested = True
            return True
        return False

    def take_held(self) -> list[float] | None:
        """The torques held while the simulation could not step (once), if any."""
        torques, self.held_torques = self.held_torques, None
        return torques

    def resend_due(self, paused: bool) -> float | None:
        """Seconds waited if the due reply is overdue (the state should go out again, and
        this counts a resend), else None."""
        if self.due is None or paused:
            return None
        waited = self.clock() - self.last_publish
        if waited < self.resend_timeout:
            return None
        self.resends += 1
        return waited


class Admit(Enum):
    """What :class:`ControllerPairing` makes of a reply's source."""

    ACCEPT = "accept"  # the paired controller
    PAIR = "pair"  # a controller now paired: the first, or (with a key) a new instance the stack started
    REFUSE = "refuse"  # any other node


class ControllerPairing:
    """Which controller's torques the simulator applies, in every mode. A change of controller
    is an explicit act, never a consequence of silence:

    * with the stack's :class:`~rabbit_msgs_py.pairing.PairingKey`: only replies signed with
      it; a new instance signing with it (a controller the stack restarted) is paired at once
      (:attr:`Admit.PAIR`, which the simulator logs);
    * without a key: the first controller to answer, until :meth:`release` (the
      ``/sim/release_controller`` service); then the next to answer.

    A silent, stopped or dead controller is never replaced by another node: lockstep holds,
    realtime damps."""

    def __init__(self, key: PairingKey | None = None) -> None:
        self.key = key
        self.controller: str | None = None  # instance id of the paired controller

    def admit(self, frame_id: str, stamp: int, torques: Sequence[float]) -> tuple[Admit, str]:
        """(verdict, the instance id the reply names) for a reply from ``frame_id``."""
        if self.key is not None:
            source = self.key.verify(frame_id, stamp, torques)
            if source is None:
                return Admit.REFUSE, source_of(frame_id)
        else:
            source = frame_id
            if self.controller is None:
                self.controller = source
                return Admit.PAIR, source
        if source == self.controller:
            return Admit.ACCEPT, source
        if self.key is None:
            return Admit.REFUSE, source
        self.controller = source
        return Admit.PAIR, source

    def release(self) -> tuple[bool, str]:
        """Forget the paired controller (no key only): (done, what to say)."""
        if self.key is not None:
            return False, ("this simulator applies torques signed with its stack's pairing key only; a controller "
                           "started with that key is paired when it answers")
        old, self.controller = self.controller, None
        return True, (f"released controller {old}: the next controller to answer is paired" if old
                      else "no controller was paired: the next to answer is")


@dataclass(frozen=True)
class TorquePublishers:
    """Who publishes ``/joint_torques``, for the log line when no reply comes: ``count`` in
    the ROS graph (a killed node stays listed for its DDS lease, up to 20 s); of those that
    declare a liveliness lease (hzd_controller_node: 1 s, ``rabbit_msgs_py.qos.TORQUE_QOS``)
    ``alive`` assert it and ``lapsed`` stopped (their process was stopped or killed);
    ``alive`` None: no such publisher seen (another kind of controller)."""

    count: int
    alive: int | None = None
    lapsed: int = 0


def silence_cause(publishers: TorquePublishers, controller: str | None, topic: str, gait: str,
                  unpaired: str | None = None, release: str = "/sim/release_controller") -> str:
    """Why no torque reply comes, as far as the simulator can tell (``topic``: the torque
    topic's full name; ``gait``: the gait topics the controller waits for; ``unpaired``: a
    controller whose replies were refused since the state went out, no key in use:
    ``release``, the service that pairs it, is named in the same line)."""
    if unpaired is not None and controller is not None:
        return (f"controller {controller} has not answered: stopped, died or busy (a killed node stays listed for up "
                f"to 20 s); controller {unpaired} answers but is not paired: 'ros2 service call {release} "
                "std_srvs/srv/Trigger' pairs the next to answer")
    if publishers.count == 0:
        return f"no node publishes {topic}: is hzd_controller_node running?"
    name = f"controller {controller}" if controller else "no controller has answered yet; a controller"
    if publishers.alive == 0 and publishers.lapsed:
        return (f"{name} stopped or died: no publisher of {topic} has asserted its liveliness for 1 s (a killed "
                "node stays listed for up to 20 s)")
    if publishers.alive:
        return f"{name} is alive but has not answered: it waits for a gait on {gait}, or is busy"
    return f"{name} has not answered: it waits for a gait on {gait}, is busy, or died"


class Pacer:
    """Paced mode: lockstep (one reply per state) kept from running ahead of the wall
    clock times ``rtf``. :meth:`wait` says how long the state at a sim time must wait
    before it goes out. When the machine cannot keep up the loop simply runs slower: after
    falling more than ``slack`` s (wall) behind it re-anchors instead of racing to catch
    up. :meth:`achieved` gives the achieved real-time factor once per ``window`` s."""

    def __init__(self, rtf: float, slack: float = 0.05, window: float = 5.0,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        if not (math.isfinite(rtf) and rtf > 0.0):
            raise ValueError(f"rtf must be a finite number > 0, got {rtf}")
        self.rtf, self.slack, self.window, self.clock = rtf, slack, window, clock
        self.anchor: tuple[float, float] | None = None  # (wall s, sim s)
        self.report_from: tuple[float, float] | None = None
        self.behind_count = 0  # re-anchorings: times the loop could not keep up

    def restart(self) -> None:
        """Pace again from the next step (start, reset, resume): the wall time spent waiting
        for a controller's first reply, or paused, is not made up by running fast."""
        self.anchor = self.report_from = None

    def begin(self, sim_time: float) -> None:
        """The step from ``sim_time`` (s) runs now: pace from here, unless already pacing."""
        if self.anchor is None:
            self.anchor = self.report_from = (self.clock(), sim_time)

    def wait(self, sim_time: float) -> float:
        """Wall seconds until the state at ``sim_time`` may go out (<= 0: now)."""
        self.begin(sim_time)
        wall0, sim0 = self.anchor
        now = self.clock()
        ahead = wall0 + (sim_time - sim0) / self.rtf - now
        if ahead < -self.slack:
            self.anchor = (now, sim_time)
            self.behind_count += 1
            return 0.0
        return ahead

    def achieved(self, sim_time: float) -> float | None:
        """The real-time factor achieved since the last report, once per ``window`` s."""
        if self.report_from is None:
            return None
        wall0, sim0 = self.report_from
        now = self.clock()
        if now - wall0 < self.window:
            return None
        self.report_from = (now, sim_time)
        return (sim_time - sim0) / (now - wall0)


class RealtimeClock:
    """Paces ticks at ``period`` s of wall-clock time without sleeping (the caller is woken
    by a timer and asks :meth:`due`): at most ``max_burst`` ticks are run back to back to
    catch up after a late wake-up; beyond that the missed ticks are skipped (sim time then
    falls behind wall time, and the caller says so) instead of stepping many times on one
    torque."""

    def __init__(self, period: float, max_burst: int = 2, clock: Callable[[], float] = time.perf_counter) -> None:
        self.period, self.max_burst, self.clock = period, max_burst, clock
        self.next_tick = clock()
        self.skipped = 0

    def restart(self) -> None:
        """The next tick is due one period from now."""
        self.next_tick = self.clock() + self.period

    def due(self) -> int:
        """How many ticks to run now (0 if the next is not due yet)."""
        now = self.clock()
        if now < self.next_tick:
            return 0
        behind = int((now - self.next_tick) / self.period) + 1
        if behind > self.max_burst:
            self.skipped += behind - 1
            self.next_tick = now + self.period
            return 1
        self.next_tick += behind * self.period
        return behind

    def overdue(self) -> float:
        """Seconds since the next tick fell due (negative: not due yet)."""
        return self.clock() - self.next_tick

    def wait_time(self) -> float:
        """Seconds until the next tick is due (0 if it is)."""
        return max(0.0, self.next_tick - self.clock())


class WatchdogEvent(Enum):
    TRIPPED = "tripped"
    RESUMED = "resumed"


@dataclass
class Watchdog:
    """Realtime torque watchdog: ``timeout`` s (wall) without a torque -> damping
    ``damping`` N m s/rad on the actuated joint rates."""

    timeout: float
    damping: float
    active: bool = False
    damped_ticks: int = 0

    def torques(self, latest: list[float], latest_wall: float, now: float, joint_rates: Sequence[float]
                ) -> tuple[list[float], WatchdogEvent | None]:
        """The torques to apply now and whether the watchdog just tripped or released.
        ``latest_wall`` < 0: no torque yet."""
        fresh = latest_wall >= 0.0 and now - latest_wall <= self.timeout
        if fresh:
            event = WatchdogEvent.RESUMED if self.active else None
            self.active = False
            return latest, event
        self.damped_ticks += 1
        event = None if self.active else WatchdogEvent.TRIPPED
        self.active = True
        return [-self.damping * rate for rate in joint_rates], event


@dataclass(frozen=True)
class Lateness:
    """What one second of realtime stepping says: ``ticks`` stepped, ``late`` of them on a
    torque older than the previous state, ``skipped`` ticks, the worst state->torque
    delay (ms); ``stop``: too many late ticks to go on (stale torques make RABBIT fall)."""

    ticks: int
    late: int
    skipped: int
    worst_ms: float
    stop: bool

    @property
    def fraction(self) -> float:
        return self.late / self.ticks if self.ticks else 0.0


class LatenessMonitor:
    """Realtime: once per ``period`` s (wall) a :class:`Lateness` when the loop fell
    behind in that period (more than 5 % late ticks, or skipped ticks), with ``stop`` set
    above ``max_late_fraction``."""

    def __init__(self, max_late_fraction: float, period: float = 1.0,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self.max_late_fraction, self.period, self.clock = max_late_fraction, period, clock
        self.start = (0, 0, 0, clock())

    def check(self, stats: "TickStatistics", skipped: int) -> Lateness | None:
        ticks, late, skipped_before, since = self.start
        now = self.clock()
        if now - since < self.period:
            return None
        self.start = (stats.ticks, stats.late_ticks, skipped, now)
        new_ticks, new_late, new_skipped = stats.ticks - ticks, stats.late_ticks - late, skipped - skipped_before
        if not new_ticks or (new_late <= 0.05 * new_ticks and not new_skipped):
            return None
        worst = max(list(stats.latencies_ms)[-new_ticks:] or [0.0])
        return Lateness(new_ticks, new_late, new_skipped, worst, new_late > self.max_late_fraction * new_ticks)


def _percentile(values: Sequence[float], q: float) -> float | None:
    if not values:
        return None
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


@dataclass
class TickStatistics:
    """What the simulator counts (read by tests, ``run_stack`` and the benchmarks)."""

    ticks: int = 0
    states_published: int = 0
    torques_received: int = 0
    torques_rejected: int = 0
    late_ticks: int = 0
    first_tick_wall: float | None = None
    last_tick_wall: float = 0.0
    latencies_ms: deque = field(default_factory=lambda: deque(maxlen=600_000))
    sent: dict = field(default_factory=dict)  # realtime: stamp (ns) -> wall time of states awaiting a torque
    last_sent: int | None = None  # stamp of the newest state sent (realtime)

    def tick(self, now: float) -> None:
        """One physics step happened at wall time ``now``."""
        self.ticks += 1
        self.last_tick_wall = now
        if self.first_tick_wall is None:
            self.first_tick_wall = now

    def state_sent(self, now: float, stamp: int, track_latency: bool) -> None:
        self.states_published += 1
        if track_latency:
            self.sent[stamp] = now
            self.last_sent = stamp

    def torque_received(self, now: float, stamp: int) -> None:
        """A reply to the state stamped ``stamp`` (ns) arrived: its latency is exact, whatever
        was lost or reordered in between."""
        self.torques_received += 1
        sent = self.sent.pop(stamp, None)
        if sent is not None:
            self.latencies_ms.append((now - sent) * 1e3)

    @property
    def awaiting_reply(self) -> bool:
        """Realtime: the newest state sent has no reply yet."""
        return self.last_sent is not None and self.last_sent in self.sent

    def forget(self) -> None:
        """The simulation was placed again: no reply is awaited."""
        self.sent.clear()
        self.last_sent = None

    def realtime_tick_due(self, now: float, lost_after: float = 0.02) -> None:
        """A realtime tick is due: late if the reply to the previous state has not come;
        states unanswered for ``lost_after`` s count as lost (dropped from the wait)."""
        if self.awaiting_reply:
            self.late_ticks += 1
        if self.sent and now - next(iter(self.sent.values())) > lost_after:
            self.sent = {stamp: t for stamp, t in self.sent.items() if now - t <= lost_after}

    def summary(self, sim_time: float, extra: dict | None = None) -> dict:
        """JSON-ready counters (None where a rate or percentile has no data)."""
        span = self.last_tick_wall - (self.first_tick_wall or 0.0)
        lat = list(self.latencies_ms)
        extra = {**(extra or {}), "latency_max_ms": max(lat) if lat else None}
        return {
            "ticks": self.ticks,
            "sim_time": sim_time,
            "states_published": self.states_published,
            "torques_received": self.torques_received,
            "torques_rejected": self.torques_rejected,
            "late_ticks": self.late_ticks,
            **extra,
            "tick_rate_hz": (self.ticks - 1) / span if self.first_tick_wall is not None and span > 0 else None,
            "late_fraction": self.late_ticks / self.ticks if self.ticks else None,
            "latency_p50_ms": _percentile(lat, 0.5),
            "latency_p99_ms": _percentile(lat, 0.99),
        }


class RecorderGate:
    """Lockstep flow control against a recorder (``/recorder/recorded_until``: the stamp of
    the newest ``/joint_states`` it wrote): the simulation steps only while the recorder has
    one of the last ``max_lag`` + 1 states published (its subscriptions keep 10: none is
    ever overwritten). Stamps, not counts: a state sent twice or a report lost or late
    cannot open a gap that never closes; the newest report is all that counts. After a
    reset, a report from before it (a later stamp) holds until the placed state is
    recorded. Disabled: never holds. Stamps in ns.

    ``wait_for_recorder`` enables it from the start (run_stack's recordings). Otherwise a
    recorder that turns up (started by hand beside a running stack) is followed from its
    first report (:meth:`follow`; it announces itself with a negative stamp before it
    subscribes, so the simulation holds before the recorder takes its first state), and let
    go once it leaves (:meth:`let_go`)."""

    def __init__(self, enabled: bool, max_lag: int = 4, timestep_ns: int = 1_000_000) -> None:
        self.enabled = enabled
        self.following = False  # enabled by a recorder that turned up (not wait_for_recorder)
        self.max_lag_ns = max_lag * timestep_ns + timestep_ns // 2
        self.recorded: int | None = None  # stamp of the newest state the recorder wrote

    def report(self, stamp: int) -> bool:
        """A report on ``/recorder/recorded_until`` (ns; negative: a recorder announced itself
        and has written nothing yet). True if it starts the following."""
        self.recorded = stamp if stamp >= 0 else None
        if self.enabled:
            return False
        self.enabled = self.following = True
        return True

    def let_go(self) -> None:
        """The followed recorder left: never hold again until another turns up."""
        self.enabled = self.following = False
        self.recorded = None

    def holds(self, published: int | None) -> bool:
        """True while the recorder lacks every state of the last ``max_lag`` + 1 up to the
        one stamped ``published`` (None: nothing published yet, nothing to wait for)."""
        if not self.enabled or published is None:
            return False
        return self.recorded is None or not (published - self.max_lag_ns <= self.recorded <= published)

    def behind(self, published: int | None) -> str:
        """Where the recorder is, for the log."""
        if self.recorded is None:
            return "it has no state yet"
        return f"it has written up to t = {self.recorded * 1e-9:.3f} s, the simulation is at " \
               f"t = {(published or 0) * 1e-9:.3f} s"
