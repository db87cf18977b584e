"""Stereo: pair decoded glyphs of both images by cell, triangulate, express per contract.

Points are triangulated in the rectified frame (undistort + rectify each camera's pixels
with its CameraInfo K, D, R, P, then intersect the rays of the two rectified projections P)
and rotated back by ``R_left^T`` into the *physical* left optical frame, as the contract
requires.  P's 3x3 part need not equal K, and the left P may carry a translation: the
triangulation is the exact linear least-squares intersection for arbitrary 3x4 P matrices.

A stereo match must also be geometrically plausible: its rectified reprojection error
(which for a horizontal rig is the vertical disparity) must be small and the point in front
of both cameras.  That rejects the rare glyph decoded to a wrong cell in one image, since
its partner in the other image then lies elsewhere on the pad.  No rclpy here.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from tactile_sl_common.camera_info import CameraCalibration, CameraInfoError, calibration_from_msg
from tactile_sl_common.settings import SettingsTable
from tactile_sl_decoder.jit import kernel

UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-12)


@dataclass
class StereoParams:
    """Plausibility gates of stereo matches."""

    max_reprojection_px: float = 1.5
    """Largest rectified reprojection error of a stereo pair (epipolar gate), px."""
    min_depth_m: float = 1e-4
    """Nearest z of a point in the left optical frame, m."""
    max_depth_m: float = 1.0
    """Farthest z of a point in the left optical frame, m."""


STEREO_SETTINGS = SettingsTable(StereoParams, fields=("max_reprojection_px",),
                                ranges={"max_reprojection_px": (0.01, 1000.0)})
"""The decoder node's live ``max_reprojection_px`` parameter."""


class StereoRig:
    """Calibration of the stereo pair, ready to rectify pixels and triangulate."""

    def __init__(self, left: CameraCalibration, right: CameraCalibration,
                 frame_id: str = "") -> None:
        left.validate("left CameraInfo")
        right.validate("right CameraInfo")
        self.left, self.right, self.frame_id = left, right, frame_id
        # Rays of the two rectified projections must not coincide (a baseline is needed).
        c_left = _centre(left.P)
        c_right = _centre(right.P)
        if c_left is None or c_right is None or np.linalg.norm(c_left - c_right) < 1e-9:
            raise CameraInfoError("left/right CameraInfo P describe no stereo baseline "
                                  "(the right P[0,3] = -fx' * baseline must not be 0)")
        self.baseline_m = float(np.linalg.norm(c_left - c_right))

    @classmethod
    def from_msgs(cls, left_msg: Any, right_msg: Any) -> "StereoRig":
        """Rig from two CameraInfo messages (rclpy or bag-decoded); CameraInfoError if bad."""
        left = calibration_from_msg(left_msg, "left CameraInfo")
        right = calibration_from_msg(right_msg, "right CameraInfo")
        header = getattr(left_msg, "header", None)
        frame = ""
        if header is not None:
            frame = header["frame_id"] if isinstance(header, dict) else str(header.frame_id)
        return cls(left, right, frame)

    def key(self) -> tuple:
        """Hashable identity of the calibration (to cache a rig across frames)."""
        return tuple(np.concatenate([c.K.ravel(), c.D.ravel(), c.R.ravel(), c.P.ravel(),
                                     [c.width, c.height]]).tolist()
                     for c in (self.left, self.right)) + (self.frame_id,)

    @staticmethod
    def rectify(cam: CameraCalibration, uv: np.ndarray) -> np.ndarray:
        """Raw (distorted) pixels (N, 2) -> rectified pixels of P (N, 2)."""
        uv = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 1, 2)
        if len(uv) == 0:
            return np.zeros((0, 2))
        if cam.distortion_model == "equidistant":
            out = cv2.fisheye.undistortPoints(uv, cam.K, cam.D, R=cam.R, P=cam.P)
        else:
            out = cv2.undistortPoints(uv, cam.K, cam.opencv_distortion(), R=cam.R, P=cam.P,
                                      criteria=UNDISTORT_CRITERIA)
        return out.reshape(-1, 2)

    def triangulate_rectified(self, uv_left: np.ndarray, uv_right: np.ndarray
                              ) -> tuple[np.ndarray, np.ndarray]:
        """Least-squares intersection in the rectified frame.

        Each pixel gives two linear equations in X (u P3 - P1) X = P1_4 - u P3_4 and
        (v P3 - P2) X = P2_4 - v P3_4 (the linear triangulation of R. Hartley and A.
        Zisserman, *Multiple View Geometry*, 2nd ed., sec. 12.2, inhomogeneous form); the four
        of a pair are solved by their normal equations, the symmetric 3 x 3 system inverted
        in closed form (adjugate / determinant) for all points at once: a quarter of the time
        of a batched LAPACK solve, and a degenerate pair gives a non-finite point (dropped by
        the caller's gates) instead of an error for the whole frame.

        Returns points (N, 3) and the larger of the two rectified reprojection errors (px).
        """
        uv_left = np.ascontiguousarray(uv_left, np.float64).reshape(-1, 2)
        uv_right = np.ascontiguousarray(uv_right, np.float64).reshape(-1, 2)
        if len(uv_left) == 0:
            return np.zeros((0, 3)), np.zeros(0)
        x = intersect_rays(uv_left, uv_right, np.ascontiguousarray(self.left.P, np.float64),
                           np.ascontiguousarray(self.right.P, np.float64))
        err = np.maximum(_reproj(self.left.P, x, uv_left), _reproj(self.right.P, x, uv_right))
        return x, err

    def triangulate(self, uv_left_raw: np.ndarray, uv_right_raw: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Raw pixel pairs -> points (N, 3) in the physical left optical frame, errors (N,)."""
        rect_l = self.rectify(self.left, uv_left_raw)
        rect_r = self.rectify(self.right, uv_right_raw)
        x_rect, err = self.triangulate_rectified(rect_l, rect_r)
        # x_phys = R_left^T x_rect  (row vectors: x_rect @ R_left)
        return x_rect @ self.left.R, err


@kernel("float64[:, ::1](float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[:, ::1])")
def intersect_rays(uv_left: np.ndarray, uv_right: np.ndarray, p_left: np.ndarray,
                   p_right: np.ndarray) -> np.ndarray:
    """Points (N, 3) of :meth:`StereoRig.triangulate_rectified`, one pass without the GIL.

    Per pair, the four equations' coefficients (u P3 - P1, v P3 - P2 of each camera) and
    right-hand sides, the normal equations and their closed-form inverse, evaluated in the
    order of the numpy version this replaced (kept in the tests): the same bits.  A
    degenerate pair gives inf / nan, not an error.
    """
    n = uv_left.shape[0]
    out = np.empty((n, 3), np.float64)
    rows = np.empty((4, 3), np.float64)
    rhs = np.empty(4, np.float64)
    a = np.empty((3, 3), np.float64)
    r = np.empty(3, np.float64)
    for k in range(n):
        for e in range(4):
            p = p_left if e < 2 else p_right
            axis = e % 2
            coord = uv_left[k, axis] if e < 2 else uv_right[k, axis]
            for i in range(3):
                rows[e, i] = coord * p[2, i] - p[axis, i]
            rhs[e] = p[axis, 3] - coord * p[2, 3]
        for i in range(3):
            for j in range(i, 3):
                a[i, j] = rows[0, i] * rows[0, j] + rows[1, i] * rows[1, j] + \
                    rows[2, i] * rows[2, j] + rows[3, i] * rows[3, j]
            r[i] = rows[0, i] * rhs[0] + rows[1, i] * rhs[1] + rows[2, i] * rhs[2] + \
                rows[3, i] * rhs[3]
        a00, a01, a02, a11, a12, a22 = a[0, 0], a[0, 1], a[0, 2], a[1, 1], a[1, 2], a[2, 2]
        c00, c01, c02 = a11 * a22 - a12 * a12, a02 * a12 - a01 * a22, a01 * a12 - a02 * a11
        c11, c12, c22 = a00 * a22 - a02 * a02, a01 * a02 - a00 * a12, a00 * a11 - a01 * a01
        inv_det = 1.0 / (a00 * c00 + a01 * c01 + a02 * c02)
        out[k, 0] = (c00 * r[0] + c01 * r[1] + c02 * r[2]) * inv_det
        out[k, 1] = (c01 * r[0] + c11 * r[1] + c12 * r[2]) * inv_det
        out[k, 2] = (c02 * r[0] + c12 * r[1] + c22 * r[2]) * inv_det
    return out


def _centre(P: np.ndarray) -> np.ndarray | None:
    """Optical centre of a 3x4 projection (its right null vector), None if degenerate."""
    M = P[:, :3]
    if abs(np.linalg.det(M)) < 1e-12:
        return None
    return -np.linalg.solve(M, P[:, 3])


def _reproj(P: np.ndarray, x: np.ndarray, uv: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):   # degenerate pairs
        proj = x @ P[:, :3].T + P[:, 3]
        pix = proj[:, :2] / proj[:, 2:3]
        err = np.linalg.norm(pix - uv, axis=1)
    return np.where(np.isfinite(err) & (proj[:, 2] > 0), err, np.inf)


@dataclass
class StereoMatch:
    """Triangulated glyph pairs (arrays of length M)."""

    xyz: np.ndarray        # (M, 3) float64, metres, physical left optical frame
    row: np.ndarray        # (M,) int32
    col: np.ndarray        # (M,) int32
    left_index: np.ndarray   # glyph index in the left image
    right_index: np.ndarray  # glyph index in the right image
    reprojection_px: np.ndarray
    rejected: int          # cell pairs dropped by the plausibility gates


def common_cells(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """The cells both (unique, >= 0) int64 arrays hold, ascending, and where each holds them.

    What ``np.intersect1d(left, right, assume_unique=True, return_indices=True)`` gives, by
    a table over the cell numbers instead of a merge sort (a tenth of its cost here).
    """
    size = int(max(left.max(initial=-1), right.max(initial=-1))) + 1
    at_left = np.full(size, -1, np.intp)
    at_left[left] = np.arange(len(left))
    at_right = np.full(size, -1, np.intp)
    at_right[right] = np.arange(len(right))
    common = np.flatnonzero((at_left >= 0) & (at_right >= 0))
    return common, at_left[common], at_right[common]


def match_and_triangulate(rig: StereoRig, uv_left: np.ndarray, cell_left: np.ndarray,
                          uv_right: np.ndarray, cell_right: np.ndarray, ncols: int,
                          params: StereoParams | None = None,
                          rect_left: np.ndarray | None = None,
                          rect_right: np.ndarray | None = None) -> StereoMatch:
    """Pair glyphs decoded to the same cell in both images, triangulate, gate.

    Cells are ``row * ncols + col`` (-1 unknown) and must be unique per image.
    ``rect_left`` / ``rect_right``: every glyph's rectified pixels (:meth:`StereoRig.rectify`
    of ``uv_left`` / ``uv_right``), if already computed; the result is the same.
    """
    p = params or StereoParams()
    cell_left = np.asarray(cell_left, dtype=np.int64)
    cell_right = np.asarray(cell_right, dtype=np.int64)
    il = np.flatnonzero(cell_left >= 0)
    ir = np.flatnonzero(cell_right >= 0)
    common, a, b = common_cells(cell_left[il], cell_right[ir])
    il, ir = il[a], ir[b]
    if rect_left is not None and rect_right is not None:
        x_rect, err = rig.triangulate_rectified(np.asarray(rect_left)[il],
                                                np.asarray(rect_right)[ir])
        xyz = x_rect @ rig.left.R
    else:
        xyz, err = rig.triangulate(np.asarray(uv_left)[il], np.asarray(uv_right)[ir])
    good = (err <= p.max_reprojection_px) & np.isfinite(xyz).all(axis=1)
    good &= (xyz[:, 2] >= p.min_depth_m) & (xyz[:, 2] <= p.max_depth_m)
    cells = common[good]
    return StereoMatch(xyz[good], (cells // ncols).astype(np.int32),
                       (cells % ncols).astype(np.int32), il[good], ir[good], err[good],
                       int((~good).sum()))
