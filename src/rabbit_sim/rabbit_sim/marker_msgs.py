""":class:`rabbit_sim.stepping.markers.Shape` records as ``visualization_msgs/MarkerArray`` (the
message side of ``/rabbit/markers``)."""

from __future__ import annotations

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker, MarkerArray

from .stepping.markers import FRAME_ID, NAMESPACE, Shape

MARKER_TYPES = {"arrow": Marker.ARROW, "cube": Marker.CUBE, "sphere": Marker.SPHERE, "cylinder": Marker.CYLINDER}


def to_marker(shape: Shape, stamp: Time) -> Marker:
    """One shape as a Marker in :data:`FRAME_ID` (``delete`` -> a DELETE of its id)."""
    marker = Marker()
    marker.header.frame_id = FRAME_ID
    marker.header.stamp = stamp
    marker.ns = NAMESPACE
    marker.id = shape.id
    if shape.kind == "delete":
        marker.action = Marker.DELETE
        return marker
    marker.type = MARKER_TYPES[shape.kind]
    marker.action = Marker.ADD
    _place(marker, shape)
    marker.points = [Point(x=x, y=y, z=z) for x, y, z in shape.points]
    return marker


def _place(marker: Marker, shape: Shape) -> None:
    """The fields of a shape that change from message to message: pose, scale, colour."""
    p, q = marker.pose.position, marker.pose.orientation
    p.x, p.y, p.z = shape.position
    q.w, q.x, q.y, q.z = shape.orientation
    marker.scale.x, marker.scale.y, marker.scale.z = shape.scale
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = shape.rgba


def marker_array(shapes: list[Shape], stamp: Time) -> MarkerArray:
    return MarkerArray(markers=[to_marker(shape, stamp) for shape in shapes])


class MarkerArrayBuilder:
    """:func:`marker_array` for a publisher at 30 Hz: keeps one Marker per shape id and
    updates only what moves (pose, scale, colour, points, action), which halves the cost of
    building the message (rclpy's field setters check every assignment)."""

    def __init__(self) -> None:
        self._markers: dict[int, Marker] = {}
        self._array = MarkerArray()

    def build(self, shapes: list[Shape], stamp: Time) -> MarkerArray:
        markers = []
        for shape in shapes:
            marker = self._markers.get(shape.id)
            if marker is None or shape.kind == "delete" or marker.action != Marker.ADD or shape.points:
                marker = self._markers[shape.id] = to_marker(shape, stamp)
            else:
                marker.header.stamp = stamp
                _place(marker, shape)
            markers.append(marker)
        self._array.markers = markers
        return self._array
