"""camera_info YAML files and CameraInfo messages."""
import cv2
import numpy as np
import pytest

from tactile_sl_common.camera_info import (
    CameraCalibration,
    CameraInfoError,
    calibration_from_msg,
    camera_info_fields,
    camera_info_yaml_text,
    load_camera_info_yaml,
    resolve_url,
    save_camera_info_yaml,
    stereo_baseline,
)

ROS_YAML = """image_width: 640
image_height: 480
camera_name: narrow_stereo/left
camera_matrix:
  rows: 3
  cols: 3
  data: [540.1, 0.0, 321.5, 0.0, 541.2, 238.9, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.08, 0.02, 0.0004, -0.0003, 0.0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
projection_matrix:
  rows: 3
  cols: 4
  data: [580.0, 0.0, 320.0, 0.0, 0.0, 580.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0]
"""


def _stereo_pair(baseline: float = 0.004) -> tuple[CameraCalibration, CameraCalibration]:
    """A rectified stereo calibration (ROS convention) of two slightly converging cameras."""
    K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])
    D = np.array([0.01, -0.02, 0.0, 0.0, 0.0])
    R, _ = cv2.Rodrigues(np.array([0.0, 0.05, 0.0]))
    T = np.array([[-baseline], [0.0], [0.0]])
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K, D, K, D, (640, 480), R, T,
                                           flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0)
    return (CameraCalibration(640, 480, K, D, R1, P1),
            CameraCalibration(640, 480, K, D, R2, P2))


class _Obj:
    def __init__(self, d):
        for k, v in d.items():
            setattr(self, k, _Obj(v) if isinstance(v, dict) else v)


def test_load_ros_camera_calibration_yaml(tmp_path):
    p = tmp_path / "left.yaml"
    p.write_text(ROS_YAML)
    c = load_camera_info_yaml(p)
    assert c.K[0, 0] == 540.1 and c.D[0] == -0.08 and c.P[0, 0] == 580.0
    assert c.camera_name == "narrow_stereo/left"
    assert load_camera_info_yaml(f"file://{p}").K[1, 1] == 541.2
    assert resolve_url("file:///x/y.yaml").as_posix() == "/x/y.yaml"


def test_round_trip_through_yaml_and_messages(tmp_path):
    left, right = _stereo_pair()
    for calib in (left, right):
        path = save_camera_info_yaml(tmp_path / "c.yaml", calib)
        back = load_camera_info_yaml(path)
        for name in "KDRP":
            np.testing.assert_array_equal(getattr(back, name), getattr(calib, name))
        fields = camera_info_fields(calib, (12, 34), "frame")
        for msg in (fields, _Obj(fields)):
            parsed = calibration_from_msg(msg)
            np.testing.assert_array_equal(parsed.P, calib.P)
    assert stereo_baseline(left, right) == pytest.approx(0.004, rel=1e-9)
    assert "rectification_matrix" in camera_info_yaml_text(left)


@pytest.mark.parametrize("text, message", [
    ("image_width: 640\nimage_height: 480\n", "camera_matrix"),
    (ROS_YAML.replace("rows: 3\n  cols: 4", "rows: 3\n  cols: 3"), "projection_matrix"),
    (ROS_YAML.replace("540.1", "0.0").replace("541.2", "0.0"), "not calibrated"),
    (ROS_YAML.replace("plumb_bob", "fisheye9"), "distortion model"),
    ("[1, 2", "YAML"),
])
def test_bad_yaml_is_a_clear_error(tmp_path, text, message):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    with pytest.raises(CameraInfoError, match=message):
        load_camera_info_yaml(p)


def test_uncalibrated_or_degenerate_messages_are_rejected():
    zero = camera_info_fields(CameraCalibration(640, 480, np.zeros((3, 3)), np.zeros(5)),
                              (0, 0), "cam")
    with pytest.raises(CameraInfoError, match="not calibrated"):
        calibration_from_msg(zero)
    left = _stereo_pair()[0]
    good = camera_info_fields(left, (0, 0), "cam")
    bad = dict(good, r=[2.0] * 9)
    with pytest.raises(CameraInfoError, match="rotation"):
        calibration_from_msg(bad)
    with pytest.raises(CameraInfoError, match="lacks field"):
        calibration_from_msg({"width": 1})
    with pytest.raises(CameraInfoError, match="no baseline"):
        stereo_baseline(left, left)
    with pytest.raises(CameraInfoError, match="no such"):
        load_camera_info_yaml("/nonexistent/x.yaml")
