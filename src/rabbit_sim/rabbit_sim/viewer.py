"""MuJoCo's own viewer on a running simulation (``--viewer``, sim_node's ``viewer``).

:class:`PassiveViewer` opens ``mujoco.viewer.launch_passive`` on the simulation's model and
data: the window draws the state the simulation computed, and :meth:`PassiveViewer.sync`
hands it the newest state at most ``max_rate`` times per wall second (a sync per 1 ms tick
would cost more than the physics). The simulation is not changed by it: the viewer's own
interaction (a mouse drag that pushes a body) is the only way it writes to the data, and
only while someone does it (``Handle.sync`` also rewrites ``xfrc_applied``, where the
simulation's pushes live: they are put back after each sync, tested bit for bit). Without a display the constructor raises
:class:`ViewerUnavailable` with one line.
"""

from __future__ import annotations

import os
import time

import mujoco


class ViewerUnavailable(RuntimeError):
    """No display, or the viewer's window could not be opened."""


class PassiveViewer:
    """A passive MuJoCo viewer window synced to ``data`` (see the module docstring)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, max_rate: float = 60.0) -> None:
        require_display()
        try:
            import mujoco.viewer

            self.handle = mujoco.viewer.launch_passive(model, data, show_left_ui=False, show_right_ui=False)
        except Exception as exc:  # noqa: BLE001 - GLFW reports a missing display in several ways
            text = str(exc).strip().splitlines()
            raise ViewerUnavailable(f"cannot open MuJoCo's viewer on display {os.environ.get('DISPLAY')!r}: "
                                    f"{text[0] if text else type(exc).__name__}") from None
        with self.handle.lock():
            self.handle.cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING  # follow the torso along the walk
            self.handle.cam.trackbodyid = model.body("torso").id
            self.handle.cam.distance = 3.0
            self.handle.cam.azimuth = 60.0
            self.handle.cam.elevation = -15.0
        self.data = data
        self.period = 1.0 / max_rate
        self._last = -1.0

    def sync(self, force: bool = False) -> None:
        """Show the current state if ``1 / max_rate`` s of wall time passed (or ``force``)."""
        now = time.perf_counter()
        if (force or now - self._last >= self.period) and self.handle.is_running():
            pushes = self.data.xfrc_applied.copy()
            self.handle.sync()
            if not self.handle.perturb.active:  # sync writes the viewer's (mouse) forces over the simulation's
                self.data.xfrc_applied[:] = pushes
            self._last = now

    def close(self, timeout: float = 2.0) -> None:
        """Close the window and wait for the viewer's thread to end (an interpreter that
        exits while it still runs can crash in GLFW)."""
        self.handle.close()
        deadline = time.perf_counter() + timeout
        while self.handle.is_running() and time.perf_counter() < deadline:
            time.sleep(0.01)
        time.sleep(0.1)  # the thread releases GLFW after it stops running


def require_display() -> None:
    """Raise :class:`ViewerUnavailable` now when there is no display (before a long run)."""
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        raise ViewerUnavailable("the viewer needs a display: DISPLAY is not set (on a headless machine run the "
                                "command under xvfb-run, or leave the viewer off)")


class ViewerObserver:
    """A per-tick observer for a simulation loop (anything with ``model``, ``data`` and its sim
    ``time`` in s): opens the viewer on the first tick and syncs it; with ``realtime`` it
    also holds the loop to the wall clock (sim time never ahead of wall time), so a fast
    ROS-free walk can be watched. Holding only waits: the physics is unchanged."""

    def __init__(self, realtime: bool = True) -> None:
        require_display()
        self.realtime = realtime
        self.viewer: PassiveViewer | None = None
        self._start_wall = 0.0
        self._start_sim = 0.0

    def __call__(self, loop, _torques=None) -> None:
        if self.viewer is None:
            self.viewer = PassiveViewer(loop.model, loop.data)
            self._start_wall, self._start_sim = time.perf_counter(), loop.time
        self.viewer.sync()
        if self.realtime:
            ahead = (loop.time - self._start_sim) - (time.perf_counter() - self._start_wall)
            if ahead > 0.002:
                time.sleep(ahead)

    def close(self) -> None:
        if self.viewer is not None:
            self.viewer.close()
            self.viewer = None
