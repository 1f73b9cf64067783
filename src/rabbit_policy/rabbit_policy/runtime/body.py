"""The body state inside the step (the learning issue's ablation row c): what a policy
deciding every N ticks sees of the robot besides the speeds, after Castillo et al. (IROS
2021, 2023: reduced-order observations of the body inside the step).

Five numbers, world frame, taken from the state the decision is made on:

| index | quantity | unit | normalised in the network by (offset, scale) |
|-------|----------|------|------------------------------------------------|
| 0 | torso pitch (positive: leaning forward) | rad | (0.0, 0.1) |
| 1 | torso pitch rate | rad/s | (0.0, 1.0) |
| 2 | gait phase tau of the stance step (0 at touchdown, 1 at the next) | 1 | (0.5, 0.5) |
| 3 | phase rate d tau / dt | 1/s | (2.0, 1.0) |
| 4 | horizontal hip velocity | m/s | (1.1, 0.4) |

The offsets and scales keep each input of a walk within about +-1 (measured on the
library's gaits at 0.7-1.5 m/s). The loops take the phase from their controller;
``policy_node`` from ``/hzd/phase``, through :class:`BodyStateBuffer`.
"""

from __future__ import annotations

from typing import Sequence

N_BODY = 5
BODY_OFFSET = (0.0, 0.0, 0.5, 2.0, 1.1)
BODY_SCALE = (0.1, 1.0, 0.5, 1.0, 0.4)


def touched_down(last_tau: float | None, tau: float) -> bool:
    """A touchdown between two decisions, seen from the phase alone: it fell back by more
    than half a step (``last_tau`` None: no decision before)."""
    return last_tau is not None and tau < last_tau - 0.5


def body_state(qpos: Sequence[float], qvel: Sequence[float], tau: float, tau_rate: float) -> tuple[float, ...]:
    """The five body inputs from the planar state (``qpos``/``qvel`` in ``JOINT_NAMES``
    order: hip x, hip z, torso pitch, ...) and the controller's phase ``tau`` and its rate
    (1/s)."""
    return (float(qpos[2]), float(qvel[2]), float(tau), float(tau_rate), float(qvel[0]))


class BodyStateBuffer:
    """The body state of a decision, built from messages that arrive in any order (the
    ROS stack: ``policy_node``). The loops' rule (:meth:`ClosedLoop.body_state
    <rabbit_policy.experiment.loop.ClosedLoop.body_state>`): a decision on the state at
    ``stamp`` sees that state's torso pitch, pitch rate and hip velocity and the phase the
    controller computed on the state before it (``stamp - tick``: the tick that produced
    this state), so :meth:`body_at` needs both. A controller that skipped that state (a
    free-running stack) is read at the newest state before ``stamp`` it answered, once it
    has answered a later one; nothing older than ``horizon`` ticks is used.

    Stamps are integers (``policy_node``: sim time in ns), ``tick`` the physics step in
    that unit. A state older than the newest one (the robot placed again) starts afresh.
    """

    def __init__(self, tick: int, horizon: int = 50) -> None:
        if not (isinstance(tick, int) and tick >= 1 and isinstance(horizon, int) and horizon >= 1):
            raise ValueError(f"tick and horizon must be whole numbers >= 1, got {tick!r} and {horizon!r}")
        self.tick = tick
        self.horizon = horizon
        self.reset()

    def reset(self) -> None:
        """Forget every state and phase (the robot was placed again)."""
        self._states: dict[int, tuple[float, float, float]] = {}  # stamp -> (pitch, pitch rate, hip velocity)
        self._phases: dict[int, tuple[float, float]] = {}  # stamp -> (tau, tau rate)
        self.newest_state: int | None = None
        self.newest_phase: int | None = None

    def add_state(self, stamp: int, qpos: Sequence[float], qvel: Sequence[float]) -> None:
        """The planar state at ``stamp`` (``JOINT_NAMES`` order)."""
        if self.newest_state is not None and stamp < self.newest_state:
            self.reset()
        self._states[stamp] = (float(qpos[2]), float(qvel[2]), float(qvel[0]))
        self.newest_state = stamp
        self._forget(self._states, stamp)

    def add_phase(self, stamp: int, tau: float, tau_rate: float) -> None:
        """The controller's phase (1) and its rate (1/s) computed on the state at ``stamp``."""
        if self.newest_phase is not None and stamp < self.newest_phase:
            self._phases.clear()  # the controller restarted on a placed state
        self._phases[stamp] = (float(tau), float(tau_rate))
        self.newest_phase = stamp
        self._forget(self._phases, stamp)

    def body_at(self, stamp: int) -> tuple[float, ...] | None:
        """The five body inputs of a decision on the state at ``stamp`` (as
        :func:`body_state`), or None while a part is still missing."""
        state = self._states.get(stamp)
        if state is None:
            return None
        phase = self._phases.get(stamp - self.tick)
        if phase is None and self.newest_phase is not None and self.newest_phase >= stamp:
            earlier = [s for s in self._phases if stamp - self.horizon * self.tick <= s < stamp]
            phase = self._phases[max(earlier)] if earlier else None
        if phase is None:
            return None
        pitch, pitch_rate, hip_velocity = state
        return (pitch, pitch_rate, phase[0], phase[1], hip_velocity)

    def expired(self, stamp: int) -> bool:
        """True once states ``horizon`` ticks newer than ``stamp`` are in and its body state
        still is not: give that decision up."""
        return (self.newest_state is not None and self.newest_state >= stamp + self.horizon * self.tick
                and self.body_at(stamp) is None)

    def _forget(self, table: dict, newest: int) -> None:
        if len(table) > 4 * self.horizon:
            oldest = newest - 2 * self.horizon * self.tick
            for stamp in [s for s in table if s < oldest]:
                del table[stamp]
