"""Stereo triangulation against exactly projected points (synthetic CameraInfo)."""
import cv2
import numpy as np
import pytest

from tactile_sl_common.camera_info import CameraCalibration, CameraInfoError, camera_info_fields
from tactile_sl_decoder.stereo.stereo import StereoRig, common_cells, match_and_triangulate


def _rig(alpha: float = 0.0, distort: bool = True):
    """Converging rig like the sensor's: 640x480, ~15 mm to the pad, rectified by OpenCV."""
    size = (640, 480)
    K1 = np.array([[820.0, 0, 318.0], [0, 815.0, 243.0], [0, 0, 1]])
    K2 = np.array([[810.0, 0, 325.0], [0, 812.0, 236.0], [0, 0, 1]])
    D1 = np.array([-0.12, 0.05, 0.001, -0.0008, 0.0]) if distort else np.zeros(5)
    D2 = np.array([-0.10, 0.03, -0.0005, 0.0006, 0.0]) if distort else np.zeros(5)
    R_rl, _ = cv2.Rodrigues(np.array([0.01, -0.25, 0.02]))     # right cam rotation (converging)
    T_rl = np.array([-0.012, 0.0004, 0.0021])                   # metres
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K1, D1, K2, D2, size, R_rl, T_rl.reshape(3, 1),
                                           alpha=alpha, flags=cv2.CALIB_ZERO_DISPARITY)
    left = CameraCalibration(640, 480, K1, D1, R1, P1)
    right = CameraCalibration(640, 480, K2, D2, R2, P2)
    return left, right, R_rl, T_rl


def _project(cam_K, cam_D, R, t, X):
    rvec, _ = cv2.Rodrigues(R)
    uv, _ = cv2.projectPoints(X.reshape(-1, 1, 3), rvec, t, cam_K, cam_D)
    return uv.reshape(-1, 2)


@pytest.mark.parametrize("alpha,distort", [(0.0, True), (0.3, True), (-1.0, False)])
def test_exact_projections_triangulate_within_1e9_m(alpha, distort):
    left, right, R_rl, T_rl = _rig(alpha, distort)
    rng = np.random.default_rng(3)
    # Points on a bumpy surface ~15 mm in front of the left camera, in its physical frame.
    X = np.column_stack([rng.uniform(-0.004, 0.004, 400), rng.uniform(-0.003, 0.003, 400),
                         0.015 + rng.uniform(-0.001, 0.001, 400)])
    uv_l = _project(left.K, left.D, np.eye(3), np.zeros(3), X)
    uv_r = _project(right.K, right.D, R_rl, T_rl, X)
    rig = StereoRig(left, right, "left_optical")
    got, err = rig.triangulate(uv_l, uv_r)
    assert np.abs(got - X).max() < 1e-9
    assert err.max() < 1e-6


def test_match_by_cell_pairs_only_common_cells_and_gates_outliers():
    left, right, R_rl, T_rl = _rig()
    rig = StereoRig(left, right)
    X = np.array([[0.0, 0.0, 0.015], [0.001, 0.0, 0.015], [0.0, 0.001, 0.0152],
                  [0.002, 0.001, 0.0149]])
    uv_l = _project(left.K, left.D, np.eye(3), np.zeros(3), X)
    uv_r = _project(right.K, right.D, R_rl, T_rl, X)
    ncols = 100
    cells_l = np.array([5, 6, 7, 8])
    # right: same cells in another order, one cell swapped to a wrong glyph, one unknown
    order = np.array([3, 0, 2, 1])
    uv_r = uv_r[order]
    cells_r = cells_l[order].copy()
    cells_r[2] = 6          # glyph of cell 7 claims cell 6 ...
    cells_r[3] = -1         # ... and the real cell-6 glyph is undecoded: cell 6 pairs wrongly
    m = match_and_triangulate(rig, uv_l, cells_l, uv_r, cells_r, ncols)
    got = dict(zip(m.col.tolist(), m.xyz))
    assert set(got) == {5, 8}          # 6 rejected (wrong partner, epipolar), 7 unmatched
    assert np.allclose(got[5], X[0], atol=1e-9) and np.allclose(got[8], X[3], atol=1e-9)
    assert m.rejected == 1


def test_degenerate_camera_info_is_rejected_with_a_clear_error():
    left, right, *_ = _rig()
    zero = CameraCalibration(640, 480, np.zeros((3, 3)), np.zeros(5))
    with pytest.raises(CameraInfoError, match="focal"):
        StereoRig(zero, right)
    with pytest.raises(CameraInfoError, match="baseline"):
        StereoRig(left, left)
    msg_l = camera_info_fields(left, (1, 2), "left_optical")
    msg_r = camera_info_fields(right, (1, 2), "right_optical")

    class Msg:
        def __init__(self, d):
            self.__dict__.update(d)

    rig = StereoRig.from_msgs(Msg(msg_l), Msg(msg_r))
    assert rig.frame_id == "left_optical"
    assert rig.baseline_m == pytest.approx(np.linalg.norm([0.012, 0.0004, 0.0021]), rel=1e-6)


def _triangulate_reference(rig, uv_left, uv_right):
    """The numpy version intersect_rays replaced, verbatim (the kernel's reference)."""
    rows, rhs = [], []
    for P, uv in ((rig.left.P, uv_left), (rig.right.P, uv_right)):
        for axis in (0, 1):
            coord = uv[:, axis]
            rows.append([coord * P[2, i] - P[axis, i] for i in range(3)])
            rhs.append(P[axis, 3] - coord * P[2, 3])

    def dot(i, j):
        return rows[0][i] * rows[0][j] + rows[1][i] * rows[1][j] + \
            rows[2][i] * rows[2][j] + rows[3][i] * rows[3][j]

    a00, a01, a02, a11, a12, a22 = dot(0, 0), dot(0, 1), dot(0, 2), dot(1, 1), dot(1, 2), \
        dot(2, 2)
    r0, r1, r2 = (rows[0][i] * rhs[0] + rows[1][i] * rhs[1] + rows[2][i] * rhs[2]
                  + rows[3][i] * rhs[3] for i in range(3))
    c00, c01, c02 = a11 * a22 - a12 * a12, a02 * a12 - a01 * a22, a01 * a12 - a02 * a11
    c11, c12, c22 = a00 * a22 - a02 * a02, a01 * a02 - a00 * a12, a00 * a11 - a01 * a01
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_det = 1.0 / (a00 * c00 + a01 * c01 + a02 * c02)
        return np.column_stack([(c00 * r0 + c01 * r1 + c02 * r2) * inv_det,
                                (c01 * r0 + c11 * r1 + c12 * r2) * inv_det,
                                (c02 * r0 + c12 * r1 + c22 * r2) * inv_det])


def test_ray_intersection_kernel_equals_the_numpy_version():
    """intersect_rays gives the numpy normal-equation solution bit for bit (degenerate too)."""
    left, right, _r, _t = _rig(0.0, True)
    rig = StereoRig(left, right, "left_optical")
    rng = np.random.default_rng(4)
    uv_left = rng.uniform(0, 640, (2000, 2))
    uv_right = uv_left + rng.normal([-40.0, 0.0], 2.0, (2000, 2))
    uv_right[:5] = uv_left[:5]                       # zero disparity: far / degenerate rays
    got, _err = rig.triangulate_rectified(uv_left, uv_right)
    np.testing.assert_array_equal(got, _triangulate_reference(rig, uv_left, uv_right))


@pytest.mark.parametrize("seed", range(5))
def test_common_cells_is_intersect1d(seed):
    rng = np.random.default_rng(seed)
    left = rng.permutation(2000)[:rng.integers(0, 900)].astype(np.int64)
    right = rng.permutation(2000)[:rng.integers(0, 900)].astype(np.int64)
    want = np.intersect1d(left, right, assume_unique=True, return_indices=True)
    for got, ref in zip(common_cells(left, right), want):
        np.testing.assert_array_equal(got, ref)
        assert got.dtype == ref.dtype
