"""How ``sim_node`` steps, without ROS: lockstep bookkeeping, realtime pacing, the torque
watchdog and the run statistics. The node only wires these to topics, services and a
thread; every rule here is unit-tested without rclpy.

* :class:`Lockstep`: one torque reply per published state. A reply arriving while none is
  due is ignored; a reset or pause requested while a reply is due takes effect when that
  reply arrives; an overdue reply makes the state go out again (:meth:`Lockstep.resend_due`).
* :class:`RealtimeClock`: one tick per timestep of wall-clock time, run from the thread
  that spins the node (no second thread waiting for the GIL); after a late wake-up it
  catches up by at most ``max_burst`` ticks and skips the rest.
* :class:`Watchdog`: in realtime, torques older than ``timeout`` s are replaced by damping
  ``-damping * joint rate``; it says when it trips and when commands resume.
* :class:`TickStatistics`: counters, late ticks and state->torque latencies; JSON-ready
  (no NaN) for ``stats_file`` and the benchmarks.

Times here are wall-clock seconds (``time.perf_counter``) unless named sim time.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from enum import Enum
from typing import Callable, Sequence


class Reply(Enum):
    """What to do with a torque reply in lockstep."""

    IGNORE = "ignore"  # none was due: a second controller, or a duplicate
    RESET = "reset"  # a reset was requested while the reply was due: reset now
    HOLD = "hold"  # paused: keep the torques until the simulation runs again
    STEP = "step"  # apply them, step, publish the next state


class Lockstep:
    """Lockstep bookkeeping (see the module docstring). ``clock``: wall time (s)."""

    def __init__(self, resend_timeout: float, clock: Callable[[], float] = time.perf_counter) -> None:
        self.resend_timeout = resend_timeout
        self.clock = clock
        self.awaiting_reply = False
        self.reset_requested = False
        self.held_torques: list[float] | None = None
        self.last_publish = 0.0
        self.resends = 0

    def published(self) -> None:
        """A state went out: its reply is due."""
        self.awaiting_reply = True
        self.last_publish = self.clock()

    def restart(self) -> None:
        """The simulation was (re)placed: nothing is due, nothing is held."""
        self.awaiting_reply = False
        self.reset_requested = False
        self.held_torques = None

    def on_reply(self, torques: list[float], paused: bool) -> Reply:
        """Classify a torque reply; the caller then resets, holds or steps."""
        if not self.awaiting_reply:
            return Reply.IGNORE
        self.awaiting_reply = False
        if self.reset_requested:
            self.reset_requested = False
            return Reply.RESET
        if paused:
            self.held_torques = torques
            return Reply.HOLD
        return Reply.STEP

    def request_reset(self) -> bool:
        """A reset was asked for; True if it must wait for the reply now due."""
        if self.awaiting_reply:
            self.reset_requested = True
            return True
        return False

    def take_held(self) -> list[float] | None:
        """The torques held while paused (once), if any."""
        torques, self.held_torques = self.held_torques, None
        return torques

    def resend_due(self, paused: bool) -> float | None:
        """Seconds waited if the due reply is overdue (the state should go out again, and
        this counts a resend), else None."""
        if not self.awaiting_reply or paused:
            return None
        waited = self.clock() - self.last_publish
        if waited < self.resend_timeout:
            return None
        self.resends += 1
        return waited


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
    unanswered: deque = field(default_factory=deque)  # realtime: wall times of states awaiting a torque

    def tick(self, now: float) -> None:
        """One physics step happened at wall time ``now``."""
        self.ticks += 1
        self.last_tick_wall = now
        if self.first_tick_wall is None:
            self.first_tick_wall = now

    def state_sent(self, now: float, track_latency: bool) -> None:
        self.states_published += 1
        if track_latency:
            self.unanswered.append(now)

    def torque_received(self, now: float) -> None:
        self.torques_received += 1
        if self.unanswered:
            self.latencies_ms.append((now - self.unanswered.popleft()) * 1e3)

    def realtime_tick_due(self, now: float, lost_after: float = 0.02) -> None:
        """A realtime tick is due: late if the reply to the previous state has not come;
        states unanswered for ``lost_after`` s count as lost."""
        if self.unanswered:
            self.late_ticks += 1
            while self.unanswered and now - self.unanswered[0] > lost_after:
                self.unanswered.popleft()

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
    """Lockstep flow control against a recorder (``/recorder/progress``): the loop does not
    step until the recorder has the first state, and holds each next state while the
    recorder is more than ``max_lag`` states behind (its subscriptions keep 10: with at most
    4 outstanding none is ever overwritten). Disabled: never holds."""

    def __init__(self, enabled: bool, max_lag: int = 4) -> None:
        self.enabled, self.max_lag = enabled, max_lag
        self.recorded = 0  # /joint_states the recorder has written
        self.state_held = False  # a state waits for the recorder

    def missed_start(self) -> bool:
        """The recorder has not written the first state yet."""
        return self.enabled and self.recorded == 0

    def lags(self, published: int) -> bool:
        """More than ``max_lag`` of the ``published`` states are not recorded yet."""
        return self.enabled and published - self.recorded > self.max_lag


class Verdict(Enum):
    """What the replies to a state asked again say about the torque sources."""

    ONE = "one"  # one live controller (another match was a dead one not expired yet)
    NONE = "none"  # no reply: no controller answering yet
    MANY = "many"  # two or more live sources: wait, probe again


class SourceProbe:
    """While two publishers match on /joint_torques (lockstep): the due state is asked again
    and the replies are counted for ``window`` s; a reply is never applied before the
    verdict."""

    def __init__(self, window: float = 0.3, clock: Callable[[], float] = time.perf_counter) -> None:
        self.window, self.clock = window, clock
        self.active = False
        self.replies = 0
        self.torques: list[float] | None = None
        self.since = 0.0

    def start(self) -> None:
        self.active, self.replies, self.torques, self.since = True, 0, None, self.clock()

    def reply(self, torques: list[float]) -> None:
        self.replies += 1
        self.torques = torques

    def verdict(self) -> Verdict | None:
        """None until the window is over; then ONE, NONE or MANY (the probe ends unless MANY)."""
        if self.clock() - self.since < self.window:
            return None
        if self.replies >= 2:
            return Verdict.MANY
        self.active = False
        return Verdict.ONE if self.replies == 1 else Verdict.NONE
