"""The experiment node of a run (:class:`Supervisor`: the speed schedule, what the walk did,
falls and stalls, the end of the run), its :class:`RunReport`, and the loop that spins it
until the run is over."""

from __future__ import annotations

import array
import time
from dataclasses import dataclass, replace

import numpy as np
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Bool, Float64, Float64MultiArray, Header, UInt32
from std_srvs.srv import SetBool

from rabbit_msgs_py import qos, topics
from rabbit_msgs_py.conversions import batch_states_or_log, stamp_to_ns
from rabbit_msgs_py.decision_ticks import TICK_NS
from rabbit_msgs_py.pairing import PairingKey, SignedBatches
from rabbit_msgs_py.polled import PolledSubscription, subscribe_drained
from rabbit_msgs_py.rejections import RejectionLog
from rabbit_msgs_py.service_callers import service_clients

from rabbit_policy.experiment.result import Touchdown, WalkResult, run_summary
from rabbit_policy.experiment.scenario import MIN_SCHEDULE_SPACING, on_tick_grid, whole_ticks
from rabbit_policy.runtime.speed_command import COMMAND_RANGE, clamp_speed

from .config import StackConfig

BATCH_TAKE_PERIOD = 0.02
"""s (wall): how often the supervisor takes the state batches waiting (a run's end, a stall and
the RTF are seen this much late at most)."""
BATCH_TAKE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2000, reliability=ReliabilityPolicy.RELIABLE)
"""The supervisor's state batches: reliable, and deep enough that a period's batches stay
while a 10 kHz flood of refused ones fills the history between takes (up to 100 kHz)."""

RESETS_NAMED = 8
"""Resets a run's report names with when and by whom; any more are counted only."""


@dataclass
class RunReport:
    """What a run of the stack did. ``result``: the walk as the fast path reports one (a
    :class:`~rabbit_policy.experiment.result.WalkResult` built from the states and touchdowns
    the supervisor saw), so ``run_stack.py --json`` and ``walk.py --json`` are the same
    report (:func:`~rabbit_policy.experiment.result.run_summary`). ``stalled``: no touchdown
    for ``StackConfig.rules.stall_after`` s, the rule of every experiment."""

    controller: str
    policy: str | None
    result: WalkResult
    wall_time: float
    completed: bool = True
    error: str | None = None
    rejected: int | None = None  # gaits the controller rejected (None: not known: it wrote no counts, killed or never started)
    decisions_lost: int | None = None  # times the controller found the policy not deciding (None: not known, as above)
    cpu_us_per_tick: dict[str, float] | None = None  # each process's CPU µs per tick over the walk (processes: bench_stack)

    fell = property(lambda self: self.result.fell)
    fall_time = property(lambda self: self.result.fall_time)
    stalled = property(lambda self: self.result.stalled)
    stall_time = property(lambda self: self.result.stall_time)
    steps = property(lambda self: self.result.steps)
    sim_time = property(lambda self: self.result.end_time)

    @property
    def segments(self) -> list[dict]:
        """Per schedule segment: ``command``, ``start``, ``end``, ``mean_speed`` (second half;
        None unless the run reached its end), ``reach_time``."""
        return self.result.segments()

    @property
    def rtf(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("nan")

    @classmethod
    def not_started(cls, config: StackConfig, error: str) -> "RunReport":
        """The report of a run that ended before any node started (``error``: why, e.g.
        ``interrupted``): nothing simulated, not completed, no gait rejected."""
        scenario = config.scenario()
        empty = WalkResult(scenario=scenario, fell=False, fall_time=None, stalled=False, stall_time=None,
                           start_time=0.0, start_x=0.0, times=np.array([]), hip_x=np.array([]), touchdowns=[],
                           peak_torque=0.0, planned_duration=on_tick_grid(config.duration))
        return cls(controller=config.controller, policy=None, result=empty, wall_time=0.0, completed=False,
                   error=error, rejected=0, decisions_lost=0)

    def take_controller_counts(self, counts: dict | None) -> None:
        """The controller's counts (``HZDControllerNode.statistics``; None: it wrote none):
        the gaits it rejected, and the times it found the policy not deciding (a due decision
        that timed out, or a silence) — a run in which the policy stopped deciding is not
        complete."""
        if counts is None:
            return
        self.rejected = int(counts.get("rejected_gaits", 0))
        self.take_decisions_lost(int(counts.get("decisions_timed_out", 0)) + int(counts.get("policy_silences", 0)))

    def take_decisions_lost(self, lost: int) -> None:
        """The times the controller found the policy not deciding: a run with any is not complete."""
        self.decisions_lost = lost
        if self.decisions_lost and self.completed:
            self.completed = False
            self.error = (f"the policy stopped deciding: the controller waited in vain {self.decisions_lost} times "
                          "(its log says when)")

    def summary(self) -> dict[str, object]:
        return {**run_summary(self.controller, self.policy, self.result, self.wall_time, self.completed, self.error,
                              decisions_lost=self.decisions_lost), "rejected": self.rejected}


EVENT_GRACE = 5.0
"""s (wall): how long a suspected stall waits for a late ``/hzd/step`` before it counts. A
reliable sample lost under load reaches its subscriber only when the writer repairs it
(Fast DDS: at its next heartbeat, up to 3 s), and every later event of that writer waits
behind it, while the states keep coming: a stack under load once reported a stall at
t = 34.8 s with the touchdowns at 33.4, 34.1 and 34.7 s merely late."""


class Supervisor(Node):
    """Runs the experiment: speed schedule, segment statistics, falls and stalls, end of run."""

    def __init__(self, config: StackConfig, context=None) -> None:
        """``config.layout`` ``attach``: the stack is not this run's (started by hand): its
        schedule's times count from the first state this node sees, and this node sends the
        schedule's commands on ``/cmd_speed`` as the stack's sim time reaches them."""
        super().__init__("run_stack_supervisor", context=context, namespace=config.namespace or None)
        self.config = config
        self.attached = config.layout == "attach"
        self._offset_ns = 0  # attached: the first state's stamp (the run's t = 0); else 0
        self._to_send: list[tuple[int, float]] = []  # attached: the schedule's commands not sent yet (ns, m/s), by time
        self._lost: tuple[int, int] | None = None  # attached: the controller's lost decisions (first heard, newest)
        key = PairingKey.parse(config.pairing_key)
        self._batches = SignedBatches(key) if key is not None else None  # keyed: the stack's simulator's only
        self._rejections = RejectionLog()  # refused batches: counted, one line a second (cheap under a flood)
        # sim times are integer ns of the stamps (seconds only in the result and the logs)
        # every distinct state's sim time (ns) and hip x (m), packed (16 bytes a tick: an hour is 58 MB)
        self._times = array.array("q")
        self._xs = array.array("d")
        self._start: tuple[int, float] | None = None  # the placed state (ns, x)
        self._pending_step: int | None = None  # a touchdown stamp (ns) whose next state has not come yet
        self._touchdown_times: list[int] = []  # ns
        self.peak_torque = 0.0
        self.fell = False
        self.fall_time: float | None = None
        self.stalled = False
        self.stall_time: float | None = None
        self._suspected: tuple[float, float] | None = None  # (sim t, wall s): no touchdown seen for stall_after
        self._last_step_ns = 0
        self._sim_ns = 0
        self._end_ns = whole_ticks(config.duration) * TICK_NS  # the run's last state
        self.first_state_wall: float | None = None
        self.last_state_wall: float | None = None
        self.last_progress_wall: float | None = None  # when sim time last moved (re-sent states do not count)
        self._speed_pub = self.create_publisher(Float64, topics.CMD_SPEED, qos.COMMAND_QOS)
        # the states are taken in bulk (every BATCH_TAKE_PERIOD s, and before any event that reads the newest),
        # never one callback a message: a flood of /sim/state_batch costs the loop's executor nothing per message
        self._states = PolledSubscription(self, Float64MultiArray, topics.STATE_BATCH, BATCH_TAKE_QOS, self._on_batch,
                                          BATCH_TAKE_PERIOD)
        self.create_subscription(Bool, topics.FALLEN, self._on_fallen, qos.STATUS_QOS)
        self.create_subscription(Header, topics.STEP, self._count_step, qos.EVENT_QOS)
        self.create_subscription(UInt32, topics.RESETS, self._on_resets, qos.STATUS_QOS)
        subscribe_drained(self, Float64, topics.CMD_SPEED, self._on_command, qos.COMMAND_QOS)  # a flood: one callback
        self.live_commands: list[tuple[float, float]] = []  # (sim s, m/s): commands sent during the run, not scheduled
        self._placements: int | None = None  # /sim/resets when first heard (the placement before the run)
        self.resets = 0  # placements since: resets nobody in the run asked for (run_stack never resets)
        self.reset_calls: list[str] = []  # each such reset heard: "t = S s, by NODES" (the nodes with a client then)
        self._pause_client = self.create_client(SetBool, topics.PAUSE_SERVICE, qos_profile=qos.SERVICE_QOS)
        self._recorded_ns = -1  # sim time (ns) of the newest state the recorder has written; -1: none yet
        if config.record:
            self.create_subscription(Clock, topics.RECORDED_UNTIL, self._on_recorded, qos.STATUS_QOS)
        if self.attached:
            self.create_subscription(UInt32, topics.DECISIONS_LOST, self._on_lost, qos.STATUS_QOS)

    def _on_lost(self, msg: UInt32) -> None:
        self._lost = (msg.data if self._lost is None else self._lost[0], msg.data)

    @property
    def decisions_lost(self) -> int | None:
        """Attached: the times the stack's controller found the policy not deciding since this
        node first heard its count (None: it never said; a controller older than the topic)."""
        return None if self._lost is None else max(0, self._lost[1] - self._lost[0])

    def schedule(self) -> tuple[tuple[float, float], ...]:
        """The run's schedule on the stack's clock (s): attached, shifted to the first state."""
        return tuple((round(t + self._offset_ns / 1e9, 9), v) for t, v in self.config.schedule)

    def _on_recorded(self, msg: Clock) -> None:
        self._recorded_ns = stamp_to_ns(msg.clock)

    @property
    def sim_time(self) -> float:
        """The newest state's sim time (s)."""
        return self._sim_ns / 1e9

    @property
    def sim_stamp(self) -> int:
        """The newest state's stamp (ns of sim time)."""
        return self._sim_ns

    @property
    def recorded_until(self) -> float:
        """The sim time (s) of the newest state the recorder has written (negative before its first)."""
        return self._recorded_ns / 1e9

    @property
    def recorder_started(self) -> bool:
        """The recorder has written a state (it says so on its progress topic)."""
        return self._recorded_ns >= 0

    @property
    def recording_complete(self) -> bool:
        """The recorder has written the last state this node saw (always true unrecorded)."""
        return not self.config.record or self._recorded_ns >= self._sim_ns

    def connected(self) -> bool:
        """True once simulator, controller and policy are all visible to this node."""
        return (
            self._pause_client.service_is_ready()
            and self.count_publishers(topics.JOINT_STATES) > 0
            and self.count_publishers(topics.JOINT_TORQUES) > 0
            and self.count_publishers(topics.ALPHA) > 0
            and self.count_subscribers(topics.CMD_SPEED) > 0
            # sim_node and, when recording, the recorder take the torques
            and self.count_subscribers(topics.JOINT_TORQUES) >= (2 if self.config.record else 1)
            and (not self.config.record or self.count_publishers(topics.RECORDED_UNTIL) > 0)
        )

    @property
    def steps(self) -> int:
        return len(self._touchdown_times)

    def request_start(self):
        """Send the first commanded speed (so a recording holds the whole command history:
        policy_node publishes the schedule's changes as it applies them, at their states) and
        ask the (paused) simulator to run; returns the service future."""
        self._speed_pub.publish(Float64(data=self.config.schedule[0][1]))
        return self._pause_client.call_async(SetBool.Request(data=False))

    @property
    def done(self) -> bool:
        """The run is over: it fell, stalled or reached its duration, with no stall suspected
        whose touchdown events may still be on their way (:data:`EVENT_GRACE`)."""
        self._settle()
        return self._suspected is None and (self.fell or self.stalled or self._sim_ns >= self._end_ns)

    def _settle(self, now: float | None = None) -> None:
        """A suspected stall that no late touchdown refuted within the grace is a stall, at the
        sim time it was suspected (a fall after it is not counted: the walk ended there)."""
        if self._suspected is None:
            return
        t, since = self._suspected
        if (time.perf_counter() if now is None else now) - since < EVENT_GRACE:
            return
        self._suspected = None
        self.stalled, self.stall_time = True, t
        if self.fell and self.fall_time is not None and self.fall_time > t:
            self.fell, self.fall_time = False, None
        self.get_logger().warning(f"t = {t:.2f} s: no touchdown for {self.config.rules.stall_after} s, stalled")

    def _count_step(self, msg: Header) -> None:
        self._states.take_all()  # the states up to now: is the one after the switch here already?
        t = stamp_to_ns(msg.stamp)  # the sim time of the state on which the stance switched
        self._touchdown_times.append(t)
        if t < self._sim_ns:  # the state after it is here already: the touchdown's time (see result())
            after = self._times[int(np.searchsorted(np.frombuffer(self._times, dtype=np.int64), t, side="right"))]
            self._last_step_ns = max(self._last_step_ns, after)
            if self._suspected is not None and not self.config.rules.stalled(self._suspected[0],
                                                                             self._last_step_ns / 1e9):
                self.get_logger().info(f"a late touchdown event (t = {t / 1e9:.3f} s) arrived: not stalled at "
                                       f"t = {self._suspected[0]:.2f} s")
                self._suspected = None
        else:
            self._pending_step = t

    def _on_command(self, msg: Float64) -> None:
        """A command on ``/cmd_speed`` (clamped into the policy's range, as it does; a bad one it
        refuses is left out): one the schedule does not hold (the policy publishes the
        schedule's own as it applies them) joins the report's segments, dated at the newest
        state this node had when it came (within the states in flight)."""
        try:
            value = clamp_speed(msg.data, *COMMAND_RANGE)
        except ValueError:
            return
        self._states.take_all()
        now = self.sim_time
        if self._start is None or any(abs(t - now) < 1.0 and v == value for t, v in self.schedule()):
            return  # before the walk (run_stack's own first command), or a scheduled change's echo
        last = self.live_commands[-1] if self.live_commands else None
        if last is not None and now - last[0] < MIN_SCHEDULE_SPACING:
            self.live_commands[-1] = (last[0], value)  # a burst: the newest value of it stands for it
        elif (last[1] if last is not None else None) != value:
            self.live_commands.append((round(now, 3), value))

    def walked_schedule(self) -> tuple[tuple[float, float], ...]:
        """The schedule the robot walked: the run's, with the live commands merged in by time
        (a scheduled change within 0.1 s of a live one is kept, the live one left out)."""
        merged = list(self.schedule())
        for t, v in self.live_commands:
            if all(abs(t - s) >= MIN_SCHEDULE_SPACING for s, _ in merged):
                merged.append((t, v))
        return tuple(sorted(merged))

    def _on_resets(self, msg: UInt32) -> None:
        """``/sim/resets``: a placement after the first is a reset this run did not ask for."""
        self._states.take_all()  # the newest state: when it was reset
        if self._placements is None:
            self._placements = msg.data
        elif msg.data > self._placements:
            self.resets += msg.data - self._placements
            self._placements = msg.data
            if len(self.reset_calls) >= RESETS_NAMED:  # a flood: counted, the graph not read again
                return
            clients = service_clients(self, topics.RESET_SERVICE)
            who = ", ".join(clients) if clients else "a node no longer in the graph"
            self.reset_calls.append(f"t = {self.sim_time:.3f} s, by {who}")
            self.get_logger().error(f"the simulation was reset at t = {self.sim_time:.3f} s by a /sim/reset call this "
                                    f"run did not make (nodes with a client of it: {who}): the run is not complete")

    def _on_fallen(self, msg: Bool) -> None:
        self._states.take_all()  # the newest state: the fall's time
        if msg.data and not self.fell:
            self.fell = True
            self.fall_time = self.sim_time

    def _on_batch(self, raw: bytes) -> None:
        """The simulator's states in a batch (``/sim/state_batch``, its serialized bytes), oldest first."""
        now = time.perf_counter()
        for state in batch_states_or_log(raw, self._states.topic, self._batch_refused, self._batches):
            self._on_state(state.stamp, state.position[0], state.effort, now)
        while self._to_send and self._to_send[0][0] <= self._sim_ns:  # attached: the commands now due
            self._speed_pub.publish(Float64(data=self._to_send.pop(0)[1]))

    def destroy_node(self) -> None:
        self._states.destroy()
        super().destroy_node()

    def _batch_refused(self, line: str) -> None:
        """A refused ``/sim/state_batch``: counted, logged at most once a second (rclpy's own
        throttle costs more per call than a 10 kHz flood leaves the loop)."""
        text = self._rejections.line("state_batch", line)
        if text is not None:
            self.get_logger().error(text)

    def _on_state(self, t: int, x: float, effort, now: float) -> None:
        """A state at ``t`` ns: hip x (m), the 7 joints' efforts (N m); ``now``: wall s it came."""
        if self.first_state_wall is None:
            self.first_state_wall = now
        self.last_state_wall = now
        if t != self._sim_ns or self.last_progress_wall is None:
            self.last_progress_wall = now
        self._sim_ns = t
        if self._start is None:
            self._start = (t, x)
            if self.attached:  # the run starts here: its schedule and end from this state on, no touchdown yet
                self._offset_ns = self._last_step_ns = t
                self._end_ns += t
                self._to_send = [(t + whole_ticks(at) * TICK_NS, v) for at, v in self.config.schedule[1:]]
        elif t > (self._times[-1] if self._times else self._start[0]):  # a state sent again is one state
            self._times.append(t)
            self._xs.append(x)
            self.peak_torque = max(self.peak_torque, *(abs(e) for e in effort[3:]))
        if self._pending_step is not None and t > self._pending_step:
            self._last_step_ns, self._pending_step = t, None
        if not self.stalled and self._suspected is None and self.config.rules.stalled(t / 1e9, self._last_step_ns / 1e9):
            # a stall, unless a late touchdown event says otherwise (EVENT_GRACE), dated at the tick the rule
            # fired, not at the state this node happened to see first (it may miss states)
            self._suspected = (self.config.rules.stall_time(self._last_step_ns / 1e9), now)
        self._settle(now)

    def result(self) -> WalkResult:
        """The walk so far, as the fast path reports one. A touchdown is dated as
        :class:`~rabbit_policy.experiment.loop.ClosedLoop` dates it: the state after the
        tick on which the stance switched (the ``/hzd/step`` stamp is the state before it),
        with that state's hip x; the foot's x is on no topic (NaN). Attached, every time
        counts from the first state seen (the run's t = 0)."""
        config = self.config
        off = self._offset_ns
        schedule = self.walked_schedule()
        if off:
            schedule = tuple((round(t - off / 1e9, 9), v) for t, v in schedule)
        scenario = replace(config.scenario(), schedule=schedule)
        t0_ns, x0 = self._start or (0, 0.0)
        t0 = (t0_ns - off) / 1e9
        times, xs = np.array(self._times, dtype=np.int64), np.array(self._xs, dtype=float)
        if self.stalled:  # the walk ended at the stall, as the fast path's does (later states came in the grace)
            keep = times <= round(self.stall_time * 1e9)  # stall_time: on the ns grid
            times, xs = times[keep], xs[keep]
        touchdowns = []
        for stamp in sorted(self._touchdown_times):
            # at the state after the switch, one tick later (the fast path's time); its hip x
            # from the first state seen from then on (this subscriber may miss states)
            i = int(np.searchsorted(times, stamp, side="right"))
            if i < len(times):  # (a switch on the last state: that tick was never simulated)
                touchdowns.append(Touchdown((stamp + TICK_NS - off) / 1e9, float("nan"), float(xs[i])))
        # the physics halts at the fall: the last state received (the newest always arrives) is the fall's
        fall_time = max(self.fall_time, self.sim_time) if self.fell and self.fall_time is not None else self.fall_time
        stall_time = self.stall_time
        if off:
            fall_time, stall_time = ((None if t is None else round(t - off / 1e9, 9)) for t in (fall_time, stall_time))
        return WalkResult(scenario=scenario, fell=self.fell, fall_time=fall_time, stalled=self.stalled,
                          stall_time=stall_time, start_time=t0, start_x=x0, times=(times - off) / 1e9, hip_x=xs,
                          touchdowns=touchdowns, peak_torque=self.peak_torque,
                          planned_duration=round(on_tick_grid(config.duration) - t0, 9))  # t0: the first state seen

    def report(self, error: str | None = None, policy: str | None = None) -> RunReport:
        wall = (
            self.last_state_wall - self.first_state_wall
            if self.first_state_wall is not None and self.last_state_wall is not None
            else 0.0
        )
        if error is None and self.resets:
            times = f"{self.resets} time" + ("s" if self.resets != 1 else "")
            error = (f"the simulation was reset {times} during the run (a /sim/reset run_stack did not make: "
                     + "; ".join(self.reset_calls) + ("; ..." if self.resets > len(self.reset_calls) else "") + ")")
        report = RunReport(controller=self.config.controller, policy=policy, result=self.result(), wall_time=wall,
                           completed=self.done and error is None, error=error)
        if self.attached and self.decisions_lost is not None:  # (a run of its own: the controller's stats file)
            report.take_decisions_lost(self.decisions_lost)
        return report


REALTIME_HALT_TIMEOUT = 3.0
"""s (wall): a realtime simulation whose time stood still this long after it started
stepping has halted (before the first torque it holds t = 0, however long that takes)."""


def spin_until_done(executor, supervisor: Supervisor, stall_timeout: float, alive=lambda: None,
                     spin_timeout: float = 0.05, stop=lambda: False, meter=None) -> str | None:
    """Start the (paused) simulation once every node is connected, then spin until the run
    is over; returns an error message or None. ``stop()`` true (a signal arrived) ends
    the run as "interrupted"; ``alive()`` returns a message when a node process died;
    ``meter`` (a :class:`~.cpu.CpuMeter`) is started at the first state.
    Progress is sim time moving: a state sent again does not count."""
    from rclpy.executors import ExternalShutdownException

    start = time.perf_counter()
    started = None
    running_since = None  # wall time the simulation was started (progress is waited for from then)
    while not supervisor.done:
        running = started is not None and started.done()
        if running and running_since is None:
            running_since = time.perf_counter()
        try:
            executor.spin_once(timeout_sec=spin_timeout if running else 0.02)
        except (KeyboardInterrupt, ExternalShutdownException):
            return "interrupted"
        if meter is not None and not meter.started and supervisor.first_state_wall is not None:
            meter.start(supervisor.sim_stamp)
        problem = "interrupted" if stop() else alive()
        if problem:
            return problem
        if started is None and supervisor.connected():
            started = supervisor.request_start()
        if not running and time.perf_counter() - start > stall_timeout:
            return f"the nodes did not connect within {stall_timeout:.0f} s"
        if running:
            waited = time.perf_counter() - max(supervisor.last_progress_wall or 0.0, running_since)
            if not supervisor.recording_complete:
                # a recorder that has written something and then stops fails the run within
                # recorder_timeout; its first state (discovery on a busy machine) may take up
                # to stall_timeout
                if not supervisor.recorder_started and waited > max(stall_timeout, supervisor.config.recorder_timeout):
                    return (f"the recorder did not write the first state within {waited:.0f} s of the start: is it "
                            "subscribed to /joint_states (sim_node's log says what it waits for)?")
                if supervisor.recorder_started and waited > supervisor.config.recorder_timeout:
                    return (f"the recorder stopped: it has written up to t = {supervisor.recorded_until:.3f} s and "
                            f"the simulation has waited for it at t = {supervisor.sim_time:.3f} s for {waited:.0f} s")
            if supervisor.config.mode == "realtime" and supervisor.sim_time > 0.0 and waited > REALTIME_HALT_TIMEOUT:
                return (f"the simulation halted at t = {supervisor.sim_time:.3f} s: realtime mode halts when the "
                        "control loop falls behind the wall clock (sim_node's log says why); --mode paced runs "
                        "slower instead")
            if waited > stall_timeout:
                return f"no simulation progress for {stall_timeout:.0f} s (at t = {supervisor.sim_time:.3f} s)"
    return None


def wait_for_recording(executor, supervisor: Supervisor, timeout: float, alive=lambda: None) -> str | None:
    """After the run: spin until the recorder has written the last state (a node stopped
    earlier could take states still in flight with it); an error message if it does not
    within ``timeout`` s."""
    deadline = time.perf_counter() + timeout
    while not supervisor.recording_complete:
        executor.spin_once(timeout_sec=0.02)
        if alive() or time.perf_counter() > deadline:
            return (f"the recorder did not write the last state (t = {supervisor.sim_time:.3f} s) within "
                    f"{timeout:.0f} s; it has up to t = {supervisor.recorded_until:.3f} s")
    return None
