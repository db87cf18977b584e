"""Touch outputs as message fields (dicts), without rclpy: one converter per message.

The same dicts are written to bags by ``tactile-sl replay`` (mcap-ros2's dynamic encoder)
and copied into rclpy messages by the decoder node, so both give the same bytes.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from tactile_sl_common.clouds import cloud_fields, pack_field
from tactile_sl_decoder.contract import SLIP_GROSS, SLIP_NO_CONTACT, SLIP_PARTIAL, SLIP_STICK
from tactile_sl_decoder.touch.contact import ContactState
from tactile_sl_decoder.touch.reference import PadPose
from tactile_sl_decoder.touch.slip import SlipEstimate
from tactile_sl_decoder.touch.stage import TouchResult

Stamp = tuple[int, int]


def header(stamp: Stamp, frame_id: str) -> dict[str, Any]:
    """std_msgs/Header fields, the stamp copied exactly."""
    return {"stamp": {"sec": int(stamp[0]), "nanosec": int(stamp[1])}, "frame_id": frame_id}


def _xyz(v: Any) -> dict[str, float]:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def field_fields(result: TouchResult, stamp: Stamp, frame_id: str) -> dict[str, Any]:
    """The contract's ``field`` cloud: x, y, z, dx, dy, dz, row, col, fx, fy, fz."""
    points = pack_field(result.position, result.displacement, result.rows, result.cols,
                        result.force)
    return cloud_fields(points, stamp, frame_id)


def wrench_fields(result: TouchResult, stamp: Stamp, frame_id: str) -> dict[str, Any]:
    """geometry_msgs/WrenchStamped: resultant force (N) and moment about the pad origin."""
    return {"header": header(stamp, frame_id),
            "wrench": {"force": _xyz(result.wrench_force), "torque": _xyz(result.wrench_moment)}}


def contact_fields(state: ContactState, stamp: Stamp, frame_id: str) -> dict[str, Any]:
    """tactile_sl_msgs/Contact."""
    return {"header": header(stamp, frame_id),
            "in_contact": bool(state.in_contact),
            "area": float(state.area),
            "centroid": _xyz(state.centroid),
            "max_depth": float(state.max_depth),
            "normal_force": float(state.normal_force),
            "shear_force": _xyz(state.shear_force),
            "peak_pressure": float(state.peak_pressure),
            "cells_in_contact": int(state.cells_in_contact),
            "region_force": [float(v) for v in state.region_force],
            "region_area": [float(v) for v in state.region_area],
            "region_centroid": [_xyz(c) for c in state.region_centroid]}


def slip_fields(slip: SlipEstimate, stamp: Stamp, frame_id: str) -> dict[str, Any]:
    """tactile_sl_msgs/Slip: the contract's fields in its order, then the additions."""
    return {"header": header(stamp, frame_id),
            "state": int(slip.state),
            "stick_ratio": float(slip.stick_ratio),
            "slip_margin": float(slip.margin),
            "friction_coefficient": float(slip.friction),
            "direction": _xyz(slip.direction),
            "centroid": _xyz(slip.centroid),
            "contact_radius": float(slip.contact_radius),
            "stick_radius": float(slip.stick_radius),
            "normal_force": float(slip.normal_force),
            "tangential_force": float(slip.tangential_force),
            "fit_residual": float(slip.fit_residual)}


# RGBA of the contact disc per state (partial slip: yellow with margin 1 to red at 0)
_STICK_RGBA = (0.15, 0.8, 0.25, 0.5)
_GROSS_RGBA = (0.9, 0.1, 0.1, 0.6)
_UNKNOWN_RGBA = (0.6, 0.6, 0.6, 0.5)
MARKER_CYLINDER, MARKER_ARROW = 3, 0         # visualization_msgs/Marker types
MARKER_ADD, MARKER_DELETEALL = 0, 3          # and actions


def _rgba(slip: SlipEstimate) -> tuple[float, float, float, float]:
    if slip.state == SLIP_GROSS:
        return _GROSS_RGBA
    if slip.state == SLIP_PARTIAL and math.isfinite(slip.margin):
        m = min(max(slip.margin, 0.0), 1.0)
        return (0.95, 0.15 + 0.75 * m, 0.1, 0.55)
    if slip.state == SLIP_STICK and math.isfinite(slip.margin):
        return _STICK_RGBA
    return _UNKNOWN_RGBA


def slip_markers(slip: SlipEstimate) -> list[dict[str, Any]]:
    """RViz markers of the slip state (visualization_msgs/Marker fields, pad frame, z = 0).

    The contact disc (radius a) coloured by state: green stick, yellow to red partial slip
    as the margin falls, red gross slip, grey when not measured; the stick disc (radius c)
    above it in green; an arrow of length a along the slip direction.  No contact: one
    DELETEALL marker, so nothing stale stays on screen.
    """
    if slip.state == SLIP_NO_CONTACT or not math.isfinite(slip.contact_radius):
        return [{"id": 0, "type": MARKER_CYLINDER, "action": MARKER_DELETEALL}]
    cx, cy, _ = slip.centroid
    a = float(slip.contact_radius)
    flat = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    out = [{"id": 0, "type": MARKER_CYLINDER, "action": MARKER_ADD,
            "position": {"x": cx, "y": cy, "z": 0.0}, "orientation": flat,
            "scale": {"x": 2 * a, "y": 2 * a, "z": 1e-4}, "color": _rgba(slip)}]
    c = float(slip.stick_radius)
    if math.isfinite(c) and c > 0:
        out.append({"id": 1, "type": MARKER_CYLINDER, "action": MARKER_ADD,
                    "position": {"x": cx, "y": cy, "z": 1e-4}, "orientation": flat,
                    "scale": {"x": 2 * c, "y": 2 * c, "z": 1e-4},
                    "color": (0.1, 0.6, 0.2, 0.9)})
    dx, dy, _ = slip.direction
    if dx or dy:
        yaw = math.atan2(dy, dx)
        out.append({"id": 2, "type": MARKER_ARROW, "action": MARKER_ADD,
                    "position": {"x": cx, "y": cy, "z": 2e-4},
                    "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2),
                                    "w": math.cos(yaw / 2)},
                    "scale": {"x": a, "y": 3e-4, "z": 5e-4}, "color": _rgba(slip)[:3] + (1.0,)})
    return out


def depth_fields(depth: np.ndarray, stamp: Stamp, frame_id: str) -> dict[str, Any]:
    """sensor_msgs/Image 32FC1 (little endian) of the depth map."""
    data = np.ascontiguousarray(depth, dtype="<f4")
    return {"header": header(stamp, frame_id), "height": int(data.shape[0]),
            "width": int(data.shape[1]), "encoding": "32FC1", "is_bigendian": 0,
            "step": int(data.shape[1] * 4), "data": data.tobytes()}


def pose_fields(pose: PadPose, stamp: Stamp, parent_frame: str) -> dict[str, Any]:
    """geometry_msgs/PoseStamped of the pad frame in the left optical frame."""
    qx, qy, qz, qw = pose.quaternion()
    return {"header": header(stamp, parent_frame),
            "pose": {"position": _xyz(pose.translation),
                     "orientation": {"x": qx, "y": qy, "z": qz, "w": qw}}}


TOUCH_TOPICS = {
    "field": "sensor_msgs/msg/PointCloud2",
    "wrench": "geometry_msgs/msg/WrenchStamped",
    "contact": "tactile_sl_msgs/msg/Contact",
    "depth": "sensor_msgs/msg/Image",
    "slip": "tactile_sl_msgs/msg/Slip",
}


def touch_messages(result: TouchResult, stamp: Stamp, frame_id: str
                   ) -> list[tuple[str, str, dict[str, Any]]]:
    """(relative topic, type, fields) of every per-frame touch output (slip if estimated)."""
    return [("field", TOUCH_TOPICS["field"], field_fields(result, stamp, frame_id)),
            ("wrench", TOUCH_TOPICS["wrench"], wrench_fields(result, stamp, frame_id)),
            ("contact", TOUCH_TOPICS["contact"], contact_fields(result.contact, stamp,
                                                                frame_id)),
            ("depth", TOUCH_TOPICS["depth"], depth_fields(result.depth, stamp, frame_id)),
            *([("slip", TOUCH_TOPICS["slip"], slip_fields(result.slip, stamp, frame_id))]
              if result.slip is not None else [])]
