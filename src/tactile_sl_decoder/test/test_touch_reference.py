"""Pad frame: the rigid fit recovers a known pose; the reference averages frames."""
import numpy as np
import pytest

from tactile_sl_decoder.touch.reference import (
    ReferenceBuilder,
    ReferenceError,
    fit_pad_pose,
    nominal_positions,
)


def _rotation(rx, ry, rz):
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    rot_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rot_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rot_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rot_z @ rot_y @ rot_x


def _grid(shape=(30, 28)):
    rows, cols = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    return rows.ravel(), cols.ravel()


@pytest.mark.parametrize("mirrored", [False, True])
def test_fit_recovers_pose_and_reports_residual(mirrored):
    rows, cols = _grid()
    nominal = nominal_positions(rows, cols, (30, 28), 5e-4, mirrored)
    rot = _rotation(0.03, -0.02, 0.5)
    t = np.array([0.0004, -0.0003, 0.015])
    rng = np.random.default_rng(1)
    measured = nominal @ rot.T + t + rng.normal(0, 2e-6, nominal.shape)
    pose = fit_pad_pose(nominal, measured)
    assert np.allclose(pose.rotation, rot, atol=2e-4)
    assert np.allclose(pose.translation, t, atol=1e-6)
    assert 2.5e-6 < pose.residual_rms < 4.5e-6   # 2 um per axis
    assert np.allclose(pose.to_pad(measured), nominal, atol=1e-5)
    q = np.array(pose.quaternion())
    assert abs(np.linalg.norm(q) - 1) < 1e-12 and q[3] >= 0
    # the quaternion encodes the same rotation
    x, y, z, w = q
    rq = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                   [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                   [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    assert np.allclose(rq, pose.rotation, atol=1e-9)


def test_wrong_pitch_shows_in_the_residual():
    rows, cols = _grid()
    nominal = nominal_positions(rows, cols, (30, 28), 5e-4)
    pose = fit_pad_pose(nominal, nominal * 1.01 + [0, 0, 0.015])
    assert pose.residual_rms > 2e-5      # 1 % pitch error: ~ 10s of um at the pad's edge


def test_degenerate_references_are_refused():
    rows, cols = _grid((1, 28))
    nominal = nominal_positions(rows, cols, (30, 28), 5e-4)
    with pytest.raises(ReferenceError, match="one line"):
        fit_pad_pose(nominal, nominal)
    with pytest.raises(ReferenceError, match="at least"):
        fit_pad_pose(nominal[:5], nominal[:5])


def test_builder_averages_cells_seen_in_half_the_frames():
    b = ReferenceBuilder(3, (2, 2))
    assert not b.add(np.array([0, 0, 1]), np.array([0, 1, 0]), np.ones((3, 3)))
    assert not b.add(np.array([0, 0]), np.array([0, 1]), 3 * np.ones((2, 3)))
    assert b.add(np.array([0]), np.array([0]), 5 * np.ones((1, 3)))
    cells, mean = b.result()
    assert list(cells) == [0, 1]                 # cell 2 seen once of 3, cell 3 never
    assert np.allclose(mean[0], 3.0) and np.allclose(mean[1], 2.0)
    # one frame's noise: the sample variance over the frames (1, 3, 5: 4; 1, 3: 2)
    assert np.allclose(b.scatter(cells), [[4.0] * 3, [2.0] * 3])
    assert np.all(np.isnan(b.scatter(np.array([2]))))       # seen once: unknown
    with pytest.raises(ValueError):
        ReferenceBuilder(0, (2, 2))


def test_a_suspect_fit_residual_is_worded_for_the_user():
    """Issue 28, item 8: a pressed reference (130.9 um RMS) was only an INFO line."""
    from tactile_sl_decoder.touch.reference import RESIDUAL_WARN_M, residual_warning

    assert residual_warning(2e-6) is None and residual_warning(RESIDUAL_WARN_M) is None
    text = residual_warning(1.309e-4)
    assert text is not None and "130.9 um RMS > 20 um" in text and "touched" in text
    assert "calibration" in text and "tare" in text
    assert residual_warning(float("nan")) is not None
