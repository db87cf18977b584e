"""Stereo capture from video files standing in for devices; lost devices come back."""
import cv2
import numpy as np
import pytest

from tactile_sl_camera.stereo_capture import CaptureConfig, StereoCapture, parse_device


def write_video(path, frames, size=(64, 48), fourcc="FFV1"):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 10, size)
    assert writer.isOpened()
    for f in frames:
        writer.write(f)
    writer.release()
    return path


def frames_with_value(values, size=(64, 48), side_by_side=False):
    out = []
    for v in values:
        f = np.full((size[1], size[0], 3), v, np.uint8)
        if side_by_side:
            f[:, size[0] // 2:] = 255 - v
        out.append(f)
    return out


class Log:
    def __init__(self):
        self.lines = []

    def __call__(self, level, text):
        self.lines.append((level, text))


def test_two_devices_deliver_synchronised_pairs(tmp_path):
    left = write_video(tmp_path / "l.avi", frames_with_value([10, 50, 90]))
    right = write_video(tmp_path / "r.avi", frames_with_value([200, 160, 120]))
    cap = StereoCapture(CaptureConfig(str(left), str(right), width=64, height=48))
    got = [cap.read() for _ in range(3)]
    assert all(g is not None for g in got)
    assert [int(g.left.mean()) for g in got] == [10, 50, 90]
    assert [int(g.right.mean()) for g in got] == [200, 160, 120]
    assert got[0].left.ndim == 2  # mono8
    cap.close()


def test_side_by_side_device_is_split(tmp_path):
    both = write_video(tmp_path / "sbs.avi", frames_with_value([30, 60], (128, 48), True),
                       (128, 48))
    cap = StereoCapture(CaptureConfig(str(both), "", side_by_side=True, width=64, height=48,
                                      encoding="bgr8"))
    g = cap.read()
    assert g.left.shape == (48, 64, 3) and g.right.shape == (48, 64, 3)
    assert int(g.left.mean()) == 30 and int(g.right.mean()) == 225


def test_lost_device_is_logged_and_retried(tmp_path):
    clock = [0.0]
    log = Log()
    left = tmp_path / "l.avi"
    right = write_video(tmp_path / "r.avi", frames_with_value([1, 2, 3, 4]))
    cap = StereoCapture(CaptureConfig(str(left), str(right), width=64, height=48,
                                      reopen_interval=1.0), log=log, clock=lambda: clock[0])
    assert cap.read() is None  # left device missing
    assert cap.read() is None
    errors = [t for lvl, t in log.lines if lvl == "error"]
    assert len(errors) == 1 and "cannot be opened" in errors[0]  # logged once, not per frame
    write_video(left, frames_with_value([100, 110]))
    assert cap.read() is None  # not yet time to retry
    clock[0] = 1.5
    g = cap.read()
    assert g is not None and int(g.left.mean()) == 100
    assert any("opened again" in t for _, t in log.lines)
    assert cap.read() is not None
    assert cap.read() is None  # end of the left file: device lost
    assert any("lost" in t for _, t in log.lines)
    clock[0] = 3.0
    assert cap.read() is not None  # reopened (a file starts over)


def test_bad_configuration_is_a_clear_error():
    with pytest.raises(ValueError, match="encoding"):
        CaptureConfig(encoding="yuv").validate()
    with pytest.raises(ValueError, match="right_device"):
        CaptureConfig(right_device="").validate()
    assert parse_device("2") == 2 and parse_device("/dev/video0") == "/dev/video0"
