"""Touch outputs as message fields (dicts), without rclpy: one converter per message.

The same dicts are written to bags by ``tactile-sl replay`` (mcap-ros2's dynamic encoder)
and copied into rclpy messages by the decoder node, so both give the same bytes.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from tactile_sl_camera.clouds import cloud_fields, pack_field
from tactile_sl_decoder.touch.contact import ContactState
from tactile_sl_decoder.touch.reference import PadPose
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
}


def touch_messages(result: TouchResult, stamp: Stamp, frame_id: str
                   ) -> list[tuple[str, str, dict[str, Any]]]:
    """(relative topic, type, fields) of every per-frame touch output."""
    return [("field", TOUCH_TOPICS["field"], field_fields(result, stamp, frame_id)),
            ("wrench", TOUCH_TOPICS["wrench"], wrench_fields(result, stamp, frame_id)),
            ("contact", TOUCH_TOPICS["contact"], contact_fields(result.contact, stamp,
                                                                frame_id)),
            ("depth", TOUCH_TOPICS["depth"], depth_fields(result.depth, stamp, frame_id))]
