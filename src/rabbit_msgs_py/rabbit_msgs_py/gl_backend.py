"""Choose MuJoCo's headless OpenGL backend before ``mujoco`` is imported.

MuJoCo reads ``MUJOCO_GL`` once, when ``mujoco`` is first imported, and an ``egl`` or
``osmesa`` choice whose library is missing makes that import fail. This module does not
import mujoco, so a script can call :func:`choose_headless_gl` first.
"""

from __future__ import annotations

import ctypes.util
import os

# backend -> the shared library it loads
HEADLESS_BACKENDS = {"egl": "EGL", "osmesa": "OSMesa"}


def choose_headless_gl() -> str:
    """Set ``MUJOCO_GL`` unless the user did: ``egl`` if libEGL is found, else
    ``osmesa`` if libOSMesa is, else ``disable`` (MuJoCo then imports without OpenGL and
    rendering reports itself unavailable). Returns the value in force."""
    if "MUJOCO_GL" not in os.environ:
        available = [name for name, lib in HEADLESS_BACKENDS.items() if ctypes.util.find_library(lib)]
        os.environ["MUJOCO_GL"] = available[0] if available else "disable"
    return os.environ["MUJOCO_GL"]


def headless() -> bool:
    """No display to open a window on (neither ``DISPLAY`` nor ``WAYLAND_DISPLAY`` set)."""
    return not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def choose_gl_when_headless() -> str | None:
    """On a headless machine, :func:`choose_headless_gl` (``egl`` where found) unless the user
    set ``MUJOCO_GL``: MuJoCo's default, GLFW, needs a display and fails there with GLFW
    warnings. With a display nothing is set (the viewer and GLFW work). Returns ``MUJOCO_GL``
    as it stands. ``import rabbit_msgs_py`` calls it, before anything of ours imports mujoco."""
    if headless():
        return choose_headless_gl()
    return os.environ.get("MUJOCO_GL")
