"""Draw ``/rabbit/markers`` side-on (the walking plane, x forward, z up) with matplotlib:
what RViz or Foxglove show, without a GUI — for a recorded bag (``scripts/render_markers.py``)
and for the tests that check the drawing against MuJoCo.

Works on any objects shaped like ``visualization_msgs/Marker`` (rclpy messages, or the ones
``rosbags`` deserialises): cylinders become rotated bars, spheres circles, cubes rectangles
(the projection of the shape on the x-z plane), arrows arrows; DELETE markers are skipped.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

ARROW, CUBE, SPHERE, CYLINDER = 0, 1, 2, 3
ADD = 0


@dataclass(frozen=True)
class Drawn:
    """A marker as drawn: ``points`` in the x-z plane (m): a cylinder's two end centres, a
    sphere's or cube's centre, an arrow's start and end; ``rgba`` 0-1."""

    id: int
    kind: str
    points: tuple[tuple[float, float], ...]
    width: float
    rgba: tuple[float, float, float, float]


def _axis(q) -> np.ndarray:
    """The local z axis of orientation ``q`` (x, y, z, w attributes) in the world frame."""
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


def drawn_shapes(markers: Iterable) -> list[Drawn]:
    """The shapes of ``markers`` as :class:`Drawn` records (no plotting)."""
    out = []
    for m in markers:
        if m.action != ADD:
            continue
        p = m.pose.position
        rgba = (m.color.r, m.color.g, m.color.b, m.color.a)
        if m.type == CYLINDER:
            half = 0.5 * m.scale.z * _axis(m.pose.orientation)
            a, b = np.array([p.x, p.y, p.z]) - half, np.array([p.x, p.y, p.z]) + half
            out.append(Drawn(m.id, "cylinder", ((a[0], a[2]), (b[0], b[2])), m.scale.x, rgba))
        elif m.type == SPHERE:
            out.append(Drawn(m.id, "sphere", ((p.x, p.z),), m.scale.x, rgba))
        elif m.type == CUBE:
            out.append(Drawn(m.id, "cube", ((p.x, p.z),), m.scale.x, rgba))
        elif m.type == ARROW and len(m.points) == 2:
            s, e = m.points
            out.append(Drawn(m.id, "arrow", ((s.x, s.z), (e.x, e.z)), m.scale.x, rgba))
    return out


def draw(ax, markers: Iterable) -> list[Drawn]:
    """Draw ``markers`` on a matplotlib axes (x-z plane, equal aspect); returns what was drawn."""
    from matplotlib.patches import Circle, FancyArrow, Polygon, Rectangle

    items = list(markers)
    drawn = drawn_shapes(items)
    cubes = {m.id: m for m in items if m.action == ADD and m.type == CUBE}
    for d in sorted(drawn, key=lambda d: {"cube": 0, "cylinder": 1, "sphere": 2, "arrow": 3}[d.kind]):
        if d.kind == "cylinder":
            a, b = np.array(d.points)
            along = (b - a) / max(np.linalg.norm(b - a), 1e-12)
            side = 0.5 * d.width * np.array([-along[1], along[0]])
            ax.add_patch(Polygon([a + side, b + side, b - side, a - side], closed=True, color=d.rgba[:3], zorder=2))
        elif d.kind == "sphere":
            ax.add_patch(Circle(d.points[0], 0.5 * d.width, color=d.rgba[:3], zorder=3))
        elif d.kind == "cube":
            m = cubes[d.id]
            (x, z), w, h = d.points[0], m.scale.x, m.scale.z
            ax.add_patch(Rectangle((x - w / 2, z - h / 2), w, h, color=d.rgba[:3], zorder=1))
        else:
            (x0, z0), (x1, z1) = d.points
            ax.add_patch(FancyArrow(x0, z0, x1 - x0, z1 - z0, width=d.width, head_width=2.2 * d.width,
                                    head_length=0.06, length_includes_head=True, color=d.rgba[:3], zorder=4))
    return drawn


def _frame(ax, drawn: list[Drawn], title: str, half_width: float) -> None:
    """Axes around the robot: ``half_width`` m either side of its mean x, the floor to 1.4 m."""
    robot = [p for d in drawn if d.kind != "cube" for p in d.points]
    cx = float(np.mean([x for x, _ in robot])) if robot else 0.0
    ax.set_xlim(cx - half_width, cx + half_width)
    ax.set_ylim(-0.1, 1.4)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, world)")
    if title:
        ax.set_title(title)


def render_png(markers: Iterable, path: Path, title: str = "", size: tuple[float, float] = (6.0, 4.5),
               dpi: int = 100) -> tuple[list[Drawn], Callable[[float, float], tuple[int, int]]]:
    """Draw ``markers`` into a PNG around the robot; returns what was drawn and a function
    from world (x, z) in m to the image's (column, row) pixel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=size, dpi=dpi)
    drawn = draw(ax, markers)
    _frame(ax, drawn, title, half_width=1.0)
    ax.set_ylabel("z (m)")
    fig.canvas.draw()
    height = fig.canvas.get_width_height()[1]
    transform = ax.transData

    def to_pixel(x: float, z: float) -> tuple[int, int]:
        col, row = transform.transform((x, z))
        return int(round(col)), int(round(height - row))

    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return drawn, to_pixel


def marker_frames(bag: Path, times: list[float], topic: str = "/rabbit/markers") -> list[tuple[float, list]]:
    """For each sim time (s), the first marker message of ``bag`` stamped at or after it:
    (stamp s, markers). Raises ``BagError`` (not a bag, unreadable) or ``ValueError`` (no
    markers, too late) with one line."""
    from rosbags.typesys import Stores, get_typestore

    from .bag import open_bag  # rosbags' writer stack only when a bag is read (as the two imports above)

    store = get_typestore(Stores.ROS2_JAZZY)
    wanted = sorted(times)
    frames: list[tuple[float, list]] = []
    reader = open_bag(bag)
    try:
        connections = [c for c in reader.connections if c.topic == topic]
        if not connections:
            raise ValueError(f"{bag} has no {topic} (record with markers on: markers_rate > 0)")
        for connection, _t, raw in reader.messages(connections=connections):
            msg = store.deserialize_cdr(raw, connection.msgtype)
            if not msg.markers:
                continue
            stamp = msg.markers[0].header.stamp.sec + msg.markers[0].header.stamp.nanosec * 1e-9
            while wanted and stamp >= wanted[0] - 1e-9:
                frames.append((stamp, list(msg.markers)))
                wanted.pop(0)
            if not wanted:
                break
    finally:
        reader.close()
    if wanted:
        raise ValueError(f"{bag}: no {topic} message at or after t = {wanted[0]} s")
    return frames


def render_strip(frames: list[tuple[float, list]], path: Path, dpi: int = 100) -> None:
    """Frames side by side (one panel each, titled with its sim time) into a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(frames), figsize=(4.0 * len(frames), 4.0), dpi=dpi, squeeze=False)
    for ax, (stamp, markers) in zip(axes[0], frames):
        _frame(ax, draw(ax, markers), f"t = {stamp:.3f} s", half_width=0.9)
    axes[0][0].set_ylabel("z (m)")
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
