"""rclpy message filling shared by the camera nodes (the field dicts come from the library)."""
from __future__ import annotations

from typing import Any

from sensor_msgs.msg import CameraInfo, Image, PointCloud2, PointField

from ..camera_info import fill_camera_info


def _header(msg: Any, stamp: Any, frame_id: str) -> None:
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id


def image_msg(fields: dict[str, Any], stamp: Any, frame_id: str) -> Image:
    """Image from :func:`tactile_sl_camera.images.image_fields` output."""
    msg = Image()
    _header(msg, stamp, frame_id)
    msg.height, msg.width = fields["height"], fields["width"]
    msg.encoding = fields["encoding"]
    msg.is_bigendian = fields["is_bigendian"]
    msg.step = fields["step"]
    msg.data = fields["data"]
    return msg


def camera_info_msg(fields: dict[str, Any], stamp: Any) -> CameraInfo:
    """CameraInfo from :func:`tactile_sl_camera.camera_info.camera_info_fields` output."""
    msg = fill_camera_info(CameraInfo(), fields)
    msg.header.stamp = stamp
    return msg


def cloud_msg(fields: dict[str, Any], stamp: Any) -> PointCloud2:
    """PointCloud2 from :func:`tactile_sl_camera.clouds.cloud_fields` output."""
    msg = PointCloud2()
    _header(msg, stamp, fields["header"]["frame_id"])
    msg.height, msg.width = fields["height"], fields["width"]
    msg.fields = [PointField(name=f["name"], offset=f["offset"], datatype=f["datatype"],
                             count=f["count"]) for f in fields["fields"]]
    msg.is_bigendian = fields["is_bigendian"]
    msg.point_step, msg.row_step = fields["point_step"], fields["row_step"]
    msg.data = fields["data"]
    msg.is_dense = fields["is_dense"]
    return msg
