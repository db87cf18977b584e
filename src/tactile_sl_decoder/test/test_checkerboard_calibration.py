"""Stereo calibration on simulator-rendered checkerboards with known ground truth."""
import numpy as np
import pytest

from tactile_sl_common.bag_io import BagWriter
from tactile_sl_common.images import image_fields
from tactile_sl_decoder.calibrate.checkerboard import calibrate_stereo, iter_bag_pairs
from tactile_sl_decoder.calibrate.result import CalibrationError
from tactile_sl_decoder.calibrate.simulate import simulated_board_views
from tactile_sl_sim.artwork import Artwork
from tactile_sl_sim.render import Renderer

PATTERN = (9, 6)
SQUARE = 0.001


@pytest.fixture(scope="module")
def renderer():
    blank = Artwork(np.ones((8, 8), np.float32), (3.5, 3.5), 4.0, 0.0005, 1, 1)
    return Renderer(blank)


@pytest.fixture(scope="module")
def views(renderer):
    return simulated_board_views(renderer, PATTERN, SQUARE, views=12, seed=1)


@pytest.mark.slow
def test_calibration_recovers_the_true_optics(renderer, views):
    result = calibrate_stereo(views, PATTERN, SQUARE)
    rig = renderer.rig
    true_baseline = np.linalg.norm(rig.T)
    baseline_err = abs(result.baseline / true_baseline - 1)
    focal_err = max(abs(est.K[i, i] / true.K[i, i] - 1)
                    for est, true in ((result.left, rig.left), (result.right, rig.right))
                    for i in (0, 1))
    print(f"\nRMS {result.rms_stereo:.3f} px, baseline error {baseline_err * 100:.3f} %, "
          f"worst focal error {focal_err * 100:.3f} %")
    assert result.pairs_used == len(views)
    assert result.rms_stereo < 0.3
    assert baseline_err < 0.01
    assert focal_err < 0.005
    # rectified right P carries -fx' * baseline
    assert -result.right.P[0, 3] / result.right.P[0, 0] == pytest.approx(result.baseline,
                                                                         rel=1e-6)


# The `tactile-sl calibrate` CLI (checkerboard mode included) is tested in
# src/tactile_sl_decoder/test/test_pattern_calibration.py, where the command now lives.


@pytest.mark.slow
def test_bag_input_pairs_by_stamp(tmp_path, views):
    path = tmp_path / "boards.mcap"
    with BagWriter(path) as bag:
        for i, (left, right) in enumerate(views[:3]):
            stamp = {"sec": 100 + i, "nanosec": 5}
            for topic, img in (("/tactile/left/image_raw", left),
                               ("/tactile/right/image_raw", right)):
                bag.write(topic, "sensor_msgs/msg/Image",
                          {"header": {"stamp": stamp, "frame_id": "f"},
                           **image_fields(img, "mono8")}, (100 + i) * 10**9 + 5)
    pairs = list(iter_bag_pairs(path))
    assert len(pairs) == 3
    assert np.array_equal(pairs[1][0], views[1][0]) and np.array_equal(pairs[1][1], views[1][1])
    with pytest.raises(CalibrationError, match="only 3 of 3"):
        calibrate_stereo(pairs, PATTERN, SQUARE)


def test_no_board_is_a_clear_error():
    blank = np.full((480, 640), 128, np.uint8)
    with pytest.raises(CalibrationError, match="found in both images of only 0"):
        calibrate_stereo([(blank, blank)] * 5, PATTERN, SQUARE)
