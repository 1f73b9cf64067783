"""When a gait policy decides and over which hip-speed samples: the one rule that the
ROS-free closed loop (:class:`~rabbit_policy.experiment.loop.ClosedLoop`) and ``policy_node``
both run, so a lockstep run of the stack and the fast path see the same observations.

Stamps are integers in any unit (the loop: sim time in ticks; the node: sim time in ns),
``tick`` the physics step in that unit. A *sample* is the state after a step (the placed
state at stamp 0 is not one: the loop never sees it as a sample); a *switch* is the state on
which the controller switched stance (``/hzd/step``'s stamp).

* Once per step (``period`` 0): a switch at ``s`` is decided once the sample after it
  (``s + tick``, the first state of the new step) is in; the observation is the mean over the
  samples after the previous decision's up to that one (the whole step just ended). The
  gait applies at the next touchdown.
* Every ``period`` ticks: at each sample whose stamp reaches the next multiple of
  ``period`` ticks since the placement (:class:`rabbit_msgs_py.decision_ticks.PeriodicDecisions`,
  the rule a controller holding its reply for the decision follows too), over the last whole step's duration (the stance
  switches known by the sample before: a switch on the state just before this sample is
  the loop's in the same tick, counted after its decision). The gait applies at once.
"""

from __future__ import annotations

import numpy as np

from rabbit_msgs_py.decision_ticks import PeriodicDecisions, check_ticks
from rabbit_policy.runtime.speed_window import Observation, SpeedWindow


class DecisionClock:
    """See the module docstring. ``window``: the longest average, in samples."""

    def __init__(self, period: int, window: int, tick: int = 1) -> None:
        check_ticks(period, minimum=0)
        if not (isinstance(tick, int) and tick >= 1):
            raise ValueError(f"tick must be a whole number >= 1 stamp unit, got {tick!r}")
        self.period = period
        self.tick = tick
        self.window = SpeedWindow(window)
        self._ticks = PeriodicDecisions(period, tick) if period else None
        self.reset()

    def reset(self) -> None:
        """The robot was placed again (stamp 0): forget the walk so far."""
        self.window.clear()
        self._switches: list[int] = []  # stance switches seen, oldest first (the last three)
        self._pending: list[int] = []  # once per step: switches waiting for the sample after them
        self._since: int | None = None  # once per step: the newest sample of the last decision's window
        self._window_start: int | None = None  # ... and where that window began (exclusive)
        if self._ticks is not None:
            self._ticks.reset()

    @property
    def newest(self) -> int | None:
        return self.window.newest_stamp

    def sample(self, stamp: int, speed: float, desired_speed: float, observe: bool = True) -> list[Observation]:
        """Add the hip speed (m/s) of the state at ``stamp`` under the command ``desired_speed``
        (m/s); returns the decisions now due (at most one every N ticks; once per step, one
        per switch whose next sample this is). A stamp older than the newest (a reset) starts
        afresh; the newest again (a state re-sent) counts once; the placed state (stamp 0) is
        no sample. Raises ``ValueError`` for a
        non-finite speed. ``observe`` False: keep the samples and the schedule, build no
        observation (every N ticks; a loop with nobody deciding on it)."""
        newest = self.window.newest_stamp
        if newest is not None and stamp == newest:
            return []  # the same state sent again (a lockstep re-send): one sample
        if stamp <= 0 or (newest is not None and stamp < newest):
            self.reset()
            if stamp <= 0:
                return []
        self.window.add(stamp, speed, desired_speed)
        if self._ticks is not None:
            if not self._ticks.due(stamp) or not observe:
                return []
            step = self._step_duration(stamp)
            return [self.window.observation(desired_speed, stamp, None if step is None else stamp - step)]
        return self._due(desired_speed)

    @property
    def next_due(self) -> int | None:
        """The stamp of the next sample that may bring a decision (every N ticks: the next
        multiple; once per step: the next sample while a switch waits), None while none can."""
        if self._ticks is not None:
            return self._ticks.next_due
        return None if not self._pending else (self.window.newest_stamp or 0) + self.tick

    def add_quiet(self, stamps: range, speeds: np.ndarray, desired_speed: float, observe: bool = True) -> None:
        """Add samples (stamps rising, after the newest) that bring no decision: as
        :meth:`sample` on each, at once (the compiled loop's ticks). With ``observe`` (someone
        decides) they must come before :attr:`next_due`; without, the decision schedule moves
        on past them as :meth:`sample` would move it."""
        newest, due = self.window.newest_stamp, self.next_due
        if (newest is not None and stamps[0] <= newest) or stamps[0] <= 0 or (
                observe and due is not None and stamps[-1] >= due):
            raise ValueError(f"samples {stamps[0]}..{stamps[-1]} are not quiet (newest {newest}, next due {due})")
        self.window.extend(stamps, speeds, desired_speed)
        if self._ticks is not None:
            if stamps[-1] < self._ticks.next_due:
                self._ticks.skip_to(stamps[-1])
            else:
                self._ticks.due(stamps[-1])  # past a due stamp nobody observes: the schedule moves on

    def switch(self, stamp: int, desired_speed: float) -> list[Observation]:
        """A stance switch on the state at ``stamp``; returns the decision now due once per
        step (if the sample after it is in already), else nothing."""
        self._switches = (self._switches + [stamp])[-3:]
        if self.period:
            return []
        self._pending.append(stamp)
        return self._due(desired_speed)

    def _due(self, desired_speed: float) -> list[Observation]:
        decided = []
        newest = self.window.newest_stamp
        while self._pending and newest is not None and self._pending[0] < newest:
            end = self._pending.pop(0) + self.tick  # the first state of the new step
            decided.append(self.window.observation(desired_speed, end, self._since))
            self._window_start, self._since = self._since, end
        return decided

    def observe(self, desired_speed: float) -> Observation:
        """What a policy asking now would see (the learning environment asks after each of its
        steps, and at the end of an episode that fell mid-step): once per step, the samples
        since the last decided window began (the step just ended, and any of the step in
        progress); every N ticks, the last step's duration up to the newest sample, with
        every switch seen so far."""
        if self.period:
            newest, known = self.window.newest_stamp, self._switches
            since = None if newest is None or len(known) < 2 else newest - (known[-1] - known[-2])
            return self.window.observation(desired_speed, None, since)
        return self.window.observation(desired_speed, None, self._window_start)

    def _step_duration(self, stamp: int) -> int | None:
        """The last whole step's duration known at ``stamp`` (switches before the previous
        sample), in stamp units; None before two switches."""
        known = [s for s in self._switches if s < stamp - self.tick]
        return known[-1] - known[-2] if len(known) >= 2 else None
