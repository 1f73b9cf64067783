"""The simulator's per-tick rules, compiled (numba ``@njit``): the one implementation of each,
called by :class:`~rabbit_sim.physics.simulation.Simulator` (and so by ``sim_node``) every step and by
the ROS-free loop's compiled inner loop (:mod:`rabbit_policy.experiment.ticks`) between its
``mj_step`` calls, which it makes through :data:`mj_step` (MuJoCo's C function, by symbol).

* :func:`fallen`: the paper's fall limits (torso pitch, hip height);
* :func:`push_rule`: after a step, end the push whose time is up and start the scheduled ones
  now due (a wrench on the torso, world frame);
* :func:`delay_torques`: torques applied some ticks after they were computed.

Compiled once per machine and cached (``cache=True``: next to this file, or numba's user-wide
cache when the install is read-only).
"""

from __future__ import annotations

from pathlib import Path

import llvmlite.binding as llvm
import mujoco
import numpy as np
from numba import njit, types


def _mujoco_library() -> Path:
    """The MuJoCo shared library the Python bindings load (beside them)."""
    package = Path(mujoco.__file__).parent
    for pattern in ("libmujoco.so*", "libmujoco*.dylib", "mujoco*.dll"):
        found = sorted(package.glob(pattern))
        if found:
            return found[0]
    raise ImportError(f"MuJoCo's shared library was not found beside its bindings in {package}")


MUJOCO_LIBRARY = _mujoco_library()
llvm.load_library_permanently(str(MUJOCO_LIBRARY))  # its symbols, for compiled code to call by name
mj_step = types.ExternalFunction("mj_step", types.void(types.intp, types.intp))
"""MuJoCo's ``mj_step(const mjModel*, mjData*)`` for compiled code, called with
``model._address`` and ``data._address``; by symbol, so the functions calling it are cached."""

# push state (Simulator.push_state): float64
PUSH_UNTIL, NEXT_PUSH, PUSH_CHANGED, PUSHES_STARTED = range(4)
PUSH_STATE_SIZE = 4
"""The push in progress ends at PUSH_UNTIL s (-1: none); NEXT_PUSH is the index of the next
scheduled push; PUSH_CHANGED is 1 after a step in which a push started or ended;
PUSHES_STARTED counts them."""

PUSH_TIME_TOLERANCE = 1e-9
"""s: a push due at t starts on the first step that ends at or after t - this (a push time is a
float read from text; the step's end is its exact tick time, :attr:`Simulator.time`)."""


@njit(cache=True)
def fallen(hip_height: float, pitch: float, min_hip_height: float, max_hip_height: float,
           max_abs_pitch: float) -> bool:
    """True when the limits are left: |pitch| (rad) >= the limit, or the hip height (m) at or
    outside (min, max)."""
    return abs(pitch) >= max_abs_pitch or hip_height <= min_hip_height or hip_height >= max_hip_height


@njit(cache=True)
def push_rule(now: float, half_step: float, state: np.ndarray, schedule: np.ndarray, wrench: np.ndarray) -> None:
    """After a step ending at ``now`` s: end a push whose time is up (within half a step,
    ``half_step`` s), then start the scheduled pushes now due (``schedule`` rows: time s, force
    N world x, duration s, by time; a later one replaces one in progress). ``wrench`` is the
    torso's row of ``xfrc_applied``."""
    state[PUSH_CHANGED] = 0.0
    if state[PUSH_UNTIL] >= 0.0 and now >= state[PUSH_UNTIL] - half_step:
        for k in range(6):
            wrench[k] = 0.0
        state[PUSH_UNTIL] = -1.0
        state[PUSH_CHANGED] = 1.0
    i = int(state[NEXT_PUSH])
    while i < schedule.shape[0] and now >= schedule[i, 0] - PUSH_TIME_TOLERANCE:
        for k in range(6):
            wrench[k] = 0.0
        wrench[0] = schedule[i, 1]
        state[PUSH_UNTIL] = now + schedule[i, 2]
        state[PUSH_CHANGED] = 1.0
        state[PUSHES_STARTED] += 1.0
        i += 1
    state[NEXT_PUSH] = float(i)


@njit(cache=True)
def delay_torques(queue: np.ndarray, count: np.ndarray, torques: np.ndarray, out: np.ndarray) -> None:
    """``out``: the torques to apply this tick given the ones computed for it (N m, four), with
    ``queue.shape[0]`` ticks of delay; until then the first ones are held. ``queue`` (ticks x
    4) and ``count`` (one entry: calls since the last clear) are the delay's state."""
    ticks = queue.shape[0]
    n = int(count[0])
    if n == 0:
        for i in range(ticks):
            for k in range(4):
                queue[i, k] = torques[k]
    slot = n % ticks
    for k in range(4):
        out[k] = queue[slot, k]
        queue[slot, k] = torques[k]
    count[0] = n + 1


def warm() -> None:
    """Load (or compile) every function here now, not on ``sim_node``'s first step (loading
    from numba's cache takes about half a second, which a first tick in real time would
    spend late)."""
    state = np.zeros(PUSH_STATE_SIZE)
    state[PUSH_UNTIL] = -1.0
    push_rule(0.0, 0.0005, state, np.zeros((0, 3)), np.zeros(6))
    delay_torques(np.zeros((1, 4)), np.zeros(1), np.zeros(4), np.zeros(4))
    fallen(0.7, 0.0, 0.6, 0.8, 0.5)
