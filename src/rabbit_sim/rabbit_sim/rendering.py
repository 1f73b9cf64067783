"""Offscreen rendering of a recorded RABBIT motion to frames and an animated GIF.

A motion is replayed from its recorded positions (``qpos`` per 1 ms tick, the model's
order); nothing is re-simulated, so the video shows exactly the walk that was measured.
The camera looks at the hip from the side (-y), following it along x.

MuJoCo picks its OpenGL backend from ``MUJOCO_GL`` when ``mujoco`` is first imported:
``egl`` (Mesa's EGL with the llvmpipe software rasteriser works without a GPU or a
display; Debian packages ``libegl1 libegl-mesa0 libgl1-mesa-dri``) or ``osmesa``
(``libosmesa6``); scripts that render call
:func:`rabbit_msgs_py.gl_backend.choose_headless_gl` before anything imports mujoco. Rendering needs no GPU: about 70-100 ms a 320 x 240 frame on one core here.
"""

from __future__ import annotations

import atexit
import os
import weakref
from pathlib import Path
from typing import Sequence

import mujoco
import numpy as np

from rabbit_msgs_py.pushes import Push

class RenderingUnavailable(RuntimeError):
    """No OpenGL context could be created (no EGL/OSMesa libraries, or a bad MUJOCO_GL)."""


def frame_indices(times: np.ndarray, fps: float) -> np.ndarray:
    """Indices of the samples nearest to every 1/fps s of ``times`` (s, increasing)."""
    if not fps > 0:
        raise ValueError("fps must be > 0")
    times = np.asarray(times, dtype=float)
    if times.size == 0:
        return np.empty(0, dtype=int)
    wanted = times[0] + np.arange(int(np.floor((times[-1] - times[0]) * fps + 1e-9)) + 1) / fps
    after = np.clip(np.searchsorted(times, wanted), 0, times.size - 1)
    before = np.clip(after - 1, 0, times.size - 1)
    nearer_before = np.abs(times[before] - wanted) <= np.abs(times[after] - wanted)
    return np.unique(np.where(nearer_before, before, after))


def side_camera(distance: float = 2.6, height: float = 0.6, elevation: float = -8.0) -> mujoco.MjvCamera:
    """A free camera on the robot's right (-y) side, ``distance`` m from the point it
    looks at, ``height`` m above the ground, looking ``elevation`` degrees down."""
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.distance, camera.azimuth, camera.elevation = distance, 90.0, elevation
    camera.lookat[:] = (0.0, 0.0, height)
    return camera


class FrameRenderer:
    """RGB frames (height x width x 3, uint8) of ``model``'s states from ``camera`` (default
    :func:`side_camera`), which follows the hip's x (m). One OpenGL context, kept until
    :meth:`close`; raises :class:`RenderingUnavailable` with one line when none can be made."""

    def __init__(self, model: mujoco.MjModel, width: int = 320, height: int = 240,
                 camera: mujoco.MjvCamera | None = None) -> None:
        if not hasattr(mujoco.gl_context, "GLContext"):  # MUJOCO_GL=disable, or no backend found
            raise RenderingUnavailable(f"MuJoCo was imported without an OpenGL backend (MUJOCO_GL="
                                       f"{os.environ.get('MUJOCO_GL', 'unset')}); install Mesa's EGL "
                                       "(libegl1 libegl-mesa0 libgl1-mesa-dri) or OSMesa (libosmesa6)")
        try:
            self.renderer = mujoco.Renderer(model, height=height, width=width)
        except Exception as exc:  # mujoco raises plain Exceptions for GL failures
            raise RenderingUnavailable(f"cannot create an OpenGL context (MUJOCO_GL="
                                       f"{os.environ.get('MUJOCO_GL', 'unset')}; on a headless machine set "
                                       f"MUJOCO_GL=egl before importing mujoco): {exc}") from exc
        self.model = model
        self.camera = camera or side_camera()
        # closed at the latest when the interpreter exits, while EGL can still free the context
        # (a renderer left to its __del__ then prints two EGLError tracebacks). weakref.finalize's
        # own exit hook is not enough: it runs after MuJoCo's eglTerminate whenever a library
        # imported before mujoco made a finalizer first (numba does); this hook, registered after
        # mujoco's, runs before it.
        self._closer = weakref.finalize(self, self.renderer.close)
        atexit.register(self._closer)

    def render(self, data: mujoco.MjData) -> np.ndarray:
        """The frame of ``data``'s state (its kinematics must be current: after a step or
        ``mj_forward``)."""
        self.camera.lookat[0] = data.qpos[0]
        self.renderer.update_scene(data, camera=self.camera)
        return self.renderer.render().copy()

    def close(self) -> None:
        atexit.unregister(self._closer)
        self._closer()  # once: an explicit close, or at exit


def render_frames(model: mujoco.MjModel, qpos: np.ndarray, width: int = 320, height: int = 240,
                  camera: mujoco.MjvCamera | None = None) -> list[np.ndarray]:
    """One RGB frame (:class:`FrameRenderer`) per row of ``qpos`` (the model's order)."""
    qpos = np.asarray(qpos, dtype=float)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq:
        raise ValueError(f"qpos must be n x {model.nq}, got shape {qpos.shape}")
    data = mujoco.MjData(model)
    renderer = FrameRenderer(model, width, height, camera)
    frames = []
    try:
        for row in qpos:
            data.qpos[:] = row
            mujoco.mj_forward(model, data)
            frames.append(renderer.render(data))
    finally:
        renderer.close()
    return frames


def caption_frames(frames: Sequence[np.ndarray], times: Sequence[float], pushes: Sequence[Push] = ()) -> list[np.ndarray]:
    """``frames`` with their sim time (s, top left) drawn in, and, on every frame inside one of
    ``pushes`` (its impulse N s, + forward), the push named in red at the top right with an
    arrow in its direction: a reader sees when a push lands and which way. New arrays; the
    input is left alone."""
    from PIL import Image, ImageDraw

    if len(times) != len(frames):
        raise ValueError(f"{len(frames)} frames but {len(times)} times")
    out = []
    for frame, t in zip(frames, times):
        image = Image.fromarray(frame)
        draw = ImageDraw.Draw(image)
        width = image.width
        label = f"t = {t:5.2f} s"
        draw.rectangle((2, 2, 8 + 6 * len(label), 15), fill=(255, 255, 255))  # legible on the sky and the floor
        draw.text((5, 3), label, fill=(0, 0, 0))
        for push in pushes:
            impulse = push.impulse
            if push.time <= t <= push.time + max(push.duration, 0.1):  # a short push shows on one frame at least
                text = f"push {impulse:+.0f} N s"
                draw.rectangle((width - 6 * len(text) - 9, 2, width - 2, 27), fill=(255, 255, 255))
                draw.text((width - 6 * len(text) - 6, 3), text, fill=(200, 0, 0))
                y, x0, x1 = 20, width - 50, width - 10
                tail, head = (x0, x1) if impulse > 0 else (x1, x0)
                draw.line((tail, y, head, y), fill=(200, 0, 0), width=3)
                sign = 1 if impulse > 0 else -1
                draw.polygon(((head, y), (head - sign * 7, y - 5), (head - sign * 7, y + 5)), fill=(200, 0, 0))
        out.append(np.asarray(image))
    return out


def save_gif(frames: Sequence[np.ndarray], path: str | Path, fps: float, hold_last: float = 0.0,
             colors: int = 48) -> Path:
    """Write ``frames`` as a looping GIF at ``fps`` with a ``colors`` palette per frame;
    ``hold_last`` s shows the last frame longer (e.g. a fall). Returns the path."""
    from PIL import Image

    if not frames:
        raise ValueError("no frames to write")
    images = [Image.fromarray(frame).quantize(colors, dither=Image.Dither.NONE) for frame in frames]
    durations = [int(round(1000.0 / fps))] * len(images)
    durations[-1] += int(round(1000.0 * hold_last))
    path = Path(path)
    images[0].save(path, save_all=True, append_images=images[1:], duration=durations, loop=0, optimize=True)
    return path
