"""The one rclpy message builder: same bytes as the field dicts, header from the dict or given."""
import array

import numpy as np
import pytest
from builtin_interfaces.msg import Time

from tactile_sl_common.clouds import CloudFormatError, cloud_fields, cloud_to_arrays, pack_points
from tactile_sl_common.images import image_fields
from tactile_sl_common.nodes.messages import (
    cloud_msg,
    image_msg,
    uint8_array,
)


def test_uint8_array_copies_any_buffer_once():
    data = np.arange(10, dtype=np.float32)
    out = uint8_array(data)
    assert isinstance(out, array.array) and out.typecode == "B"
    assert out.tobytes() == data.tobytes()
    assert uint8_array(out) is out
    assert uint8_array(b"\x01\x02").tolist() == [1, 2]


def test_cloud_msg_carries_the_fields_bytes_and_their_header():
    xyz = np.array([[0.001, 0.002, 0.015], [0.0, -0.001, 0.0151]])
    points = pack_points(xyz, np.array([3, 4]), np.array([5, 6]))
    fields = cloud_fields(points, (12, 345), "tactile_left_optical_frame")
    msg = cloud_msg(fields)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (12, 345)
    assert msg.header.frame_id == "tactile_left_optical_frame"
    assert bytes(msg.data) == fields["data"]
    assert (msg.width, msg.point_step, msg.row_step) == (2, fields["point_step"],
                                                         fields["row_step"])
    back = cloud_to_arrays(msg)
    np.testing.assert_array_equal(back["row"], [3, 4])
    later = cloud_msg(fields, Time(sec=99, nanosec=1))
    assert (later.header.stamp.sec, later.header.stamp.nanosec) == (99, 1)


def test_image_msg_takes_a_given_stamp_and_frame_over_the_dicts():
    pixels = (np.arange(12, dtype=np.uint8) * 20).reshape(3, 4)
    fields = image_fields(pixels, "mono8")
    msg = image_msg(fields, Time(sec=7, nanosec=8), "cam")
    assert (msg.height, msg.width, msg.step, msg.encoding) == (3, 4, 4, "mono8")
    assert bytes(msg.data) == pixels.tobytes()
    assert msg.header.frame_id == "cam" and msg.header.stamp.sec == 7


def test_pack_points_refuses_two_points_for_one_cell():
    xyz = np.zeros((4, 3))
    pack_points(xyz, np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1]))     # all distinct
    pack_points(xyz[:1], np.array([7]), np.array([7]))                    # one point
    with pytest.raises(CloudFormatError, match="same cell"):
        pack_points(xyz, np.array([0, 1, 2, 1]), np.array([5, 6, 7, 6]))
