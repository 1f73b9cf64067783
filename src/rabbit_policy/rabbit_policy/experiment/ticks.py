"""The closed loop's ticks between two Python events, compiled (numba ``@njit``).

:func:`run_ticks` is the inner loop of :class:`~rabbit_policy.experiment.loop.ClosedLoop`: per
tick the HZD law (:func:`rabbit_hzd_controller.law.control`), the torque delay, ``mj_step``
(MuJoCo's C function, called directly), the push rule (:mod:`rabbit_sim.physics.compiled`), the record
of time, hip position and speed, and the stop rules below; it returns after ``n`` ticks, or
after a tick that touched down, fell, rolled back or reached the section phase. The loop chooses ``n`` so that nothing
Python decides (a decision, a command change, a stall by time, an observer) falls strictly
inside: those happen between calls, on the same state as before. Every rule here is the one
implementation the node stack runs too (the controller node and ``sim_node`` call the same
compiled functions tick by tick).

The loop state ``state`` (float64, :data:`LOOP_STATE_SIZE`): the tick (steps since the
placement, a whole number: the :class:`~rabbit_sim.physics.simulation.Simulator`'s count) and the tick in
ns, from which each tick's sim time is ``tick x tick_ns / 1e9`` s (the float nearest the exact
stamp, never MuJoCo's drifting float sum), the timestep (s), the fall limits (m, m,
rad), the early stall rule's length (ticks, 0: off) and its count, the peak |torque| (N m), the
two foot sites, the stop flags of the last tick (:data:`FELL`, :data:`ROLLED_BACK`,
:data:`SECTION_REACHED`) and the section phase (+inf: none; the Poincaré return map stops at it).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from rabbit_hzd_controller import law
from rabbit_sim.physics import compiled as sim_rules

TICK, TICK_NS, TIMESTEP, MIN_HEIGHT, MAX_HEIGHT, MAX_PITCH, ROLL_BACK_TICKS, ROLLING, PEAK, LEFT_FOOT, RIGHT_FOOT, \
    STOP, SECTION = range(13)
LOOP_STATE_SIZE = 13
FELL, ROLLED_BACK, SECTION_REACHED = 1, 2, 4
"""Bits of ``state[STOP]``."""


@njit(cache=True)
def stop_rules(state: np.ndarray, qpos: np.ndarray, qvel: np.ndarray, site_xpos: np.ndarray, stance: float,
               tau: float) -> None:
    """After a step: ``state[STOP]`` gets :data:`FELL` when the fall limits are left,
    :data:`ROLLED_BACK` once the hip has been behind its stance foot (``stance`` 0 left, 1
    right) and moving backward for the early stall rule's number of ticks running, and
    :data:`SECTION_REACHED` when the tick's phase ``tau`` is at or past ``state[SECTION]``."""
    flags = 0.0
    if tau >= state[SECTION]:
        flags += SECTION_REACHED
    if sim_rules.fallen(qpos[1], qpos[2], state[MIN_HEIGHT], state[MAX_HEIGHT], state[MAX_PITCH]):
        flags += FELL
    if state[ROLL_BACK_TICKS] > 0.0:
        foot = int(state[LEFT_FOOT] if stance == 0.0 else state[RIGHT_FOOT])
        if qvel[0] < 0.0 and qpos[0] < site_xpos[foot, 0]:
            state[ROLLING] += 1.0
            if state[ROLLING] >= state[ROLL_BACK_TICKS]:
                flags += ROLLED_BACK
        else:
            state[ROLLING] = 0.0
    state[STOP] = flags


@njit(cache=True)
def run_ticks(model: int, data: int, qpos: np.ndarray, qvel: np.ndarray, ctrl: np.ndarray, site_xpos: np.ndarray,
              cfg: np.ndarray, controller: np.ndarray, gaits: np.ndarray, delay_queue: np.ndarray,
              delay_count: np.ndarray, push_state: np.ndarray, push_schedule: np.ndarray, wrench: np.ndarray,
              state: np.ndarray, times: np.ndarray, xs: np.ndarray, speeds: np.ndarray, applied: np.ndarray,
              n: int) -> int:
    """Up to ``n`` ticks (see the module docstring); returns how many ran. ``model`` and
    ``data`` are the MuJoCo structs' addresses, the arrays views of their fields (``wrench``:
    the torso's row of ``xfrc_applied``); ``times``, ``xs`` and ``speeds`` receive each tick's
    sim time (s), hip x (m) and hip velocity (m/s); ``applied`` the last tick's torques (N m)."""
    torques = np.empty(4)
    delayed = delay_queue.shape[0] > 0
    half_step = 0.5 * state[TIMESTEP]
    peak = state[PEAK]
    k = 0
    while k < n:
        law.control(cfg, controller, gaits, qpos, qvel, torques)
        if delayed:
            sim_rules.delay_torques(delay_queue, delay_count, torques, applied)
        else:
            for j in range(4):
                applied[j] = torques[j]
        for j in range(4):
            ctrl[j] = applied[j]
            tq = applied[j]
            if tq > peak:
                peak = tq
            elif -tq > peak:
                peak = -tq
        sim_rules.mj_step(model, data)
        tick = state[TICK] + 1.0
        state[TICK] = tick
        now = tick * state[TICK_NS] / 1e9
        sim_rules.push_rule(now, half_step, push_state, push_schedule, wrench)
        times[k] = now
        xs[k] = qpos[0]
        speeds[k] = qvel[0]
        k += 1
        stop_rules(state, qpos, qvel, site_xpos, controller[law.STANCE], controller[law.TAU])
        if state[STOP] != 0.0 or controller[law.TOUCHDOWN] != 0.0:
            break
    state[PEAK] = peak
    return k
