"""Health of a stereo calibration, judged in place from the untouched pad (no rclpy).

The untouched pad of the assembled sensor is a known flat target: cell (r, c) rests at
((c - (cols-1)/2) * pitch, (r - (rows-1)/2) * pitch, 0) in the **pad frame** (contract; x
reversed when the cameras see the artwork mirrored).  From the cells decoded in both images
of untouched frames, with a calibration under test:

- **reprojection residual**: RMS of the rectified reprojection error of the triangulated
  cells (for a rectified pair, half the vertical disparity); a knocked camera or a wrong K
  shows up as vertical disparity;
- **flatness**: RMS height, over the cells, of the least-squares quadratic surface fitted to
  the triangulated cells' distances from their least-squares plane (SVD of the centred
  points): the systematic bow a wrong focal length or distortion gives a flat pad; the
  per-cell scatter about that surface (centroid noise) is reported apart;
- **pitch error**: scale s - 1 of the similarity transform that best maps the pad-frame
  rest positions onto the triangulated cells [Umeyama 1991, "Least-squares estimation of
  transformation parameters between two point patterns", IEEE TPAMI 13(4)]; a wrong
  baseline, focal length or convergence angle scales the triangulated pad;
- **pad pose**: that transform's rotation and translation (pad frame in the physical left
  optical frame), reported as tilt from the left optical axis and distance.

:func:`calibration_health` returns a :class:`HealthReport` with a verdict against
:class:`HealthLimits` (documented in docs/calibration.md).  :func:`refine_extrinsics`
re-estimates the stereo extrinsics from the same frames with the intrinsics fixed.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from tactile_sl_common.camera_info import CameraCalibration
from tactile_sl_decoder.calibrate.result import CalibrationError, StereoCalibrationResult
from tactile_sl_decoder.glyphs import Glyphs
from tactile_sl_decoder.stereo.stereo import StereoRig

from .views import CameraView, PatternTarget, StereoView


@dataclass
class HealthLimits:
    """Limits past which a calibration is reported as drifted (see docs/calibration.md)."""

    max_reprojection_px: float = 0.15   # RMS rectified reprojection error
    max_flatness_m: float = 1.5e-6      # RMS systematic bow (quadratic) off the best plane
    max_pitch_error: float = 0.004      # |s - 1| of the similarity fit
    min_points: int = 50                # cells decoded in both images, at least


@dataclass
class HealthReport:
    """Figures of one health check and their verdict."""

    points: int
    reprojection_rms_px: float = float("nan")
    vertical_disparity_px: float = float("nan")   # mean rectified v_left - v_right
    flatness_rms_m: float = float("nan")         # systematic bow (quadratic surface)
    scatter_rms_m: float = float("nan")          # per-cell noise about that surface
    behind: int = 0                               # cells triangulated behind the cameras
    pitch_error: float = float("nan")             # relative, s - 1
    fit_rms_m: float = float("nan")               # residual of the similarity fit
    R_pad: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))
    t_pad_m: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    tilt_deg: float = float("nan")                # pad normal vs the left optical axis
    problems: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when every figure is within its limit."""
        return not self.problems

    @property
    def verdict(self) -> str:
        return "PASS" if self.ok else "FAIL"

    def summary(self) -> str:
        """The figures and the verdict, a few lines."""
        lines = [
            f"cells triangulated: {self.points}",
            f"reprojection residual RMS: {self.reprojection_rms_px:.3f} px (mean vertical "
            f"disparity {self.vertical_disparity_px:+.3f} px)",
            f"pad flatness RMS: {self.flatness_rms_m * 1e6:.2f} um (per-cell scatter "
            f"{self.scatter_rms_m * 1e6:.2f} um)",
            f"pitch error: {100 * self.pitch_error:+.3f} %",
            f"pad pose: tilt {self.tilt_deg:.2f} deg, origin ({self.t_pad_m[0] * 1e3:.3f}, "
            f"{self.t_pad_m[1] * 1e3:.3f}, {self.t_pad_m[2] * 1e3:.3f}) mm in the left "
            "optical frame",
            f"verdict: {self.verdict}"]
        lines += [f"  - {p}" for p in self.problems]
        return "\n".join(lines)

    def as_dict(self) -> dict[str, float | int | str]:
        """Flat figures (for diagnostics key/values)."""
        return {"points": self.points, "reprojection_rms_px": self.reprojection_rms_px,
                "vertical_disparity_px": self.vertical_disparity_px,
                "flatness_rms_m": self.flatness_rms_m, "pitch_error": self.pitch_error,
                "tilt_deg": self.tilt_deg, "distance_m": float(self.t_pad_m[2]),
                "verdict": self.verdict, "problems": "; ".join(self.problems)}


def similarity_fit(src: np.ndarray, dst: np.ndarray
                   ) -> tuple[float, np.ndarray, np.ndarray]:
    """s, R, t minimising sum |dst - (s R src + t)|^2, R a proper rotation [Umeyama 1991]."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    cov = b.T @ a / len(src)
    U, S, Vt = np.linalg.svd(cov)
    E = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        E[2, 2] = -1.0
    R = U @ E @ Vt
    var_s = float((a * a).sum() / len(src))
    s = float(np.trace(np.diag(S) @ E) / var_s)
    return s, R, mu_d - s * R @ mu_s


def _flatness(xyz: np.ndarray) -> tuple[float, float]:
    """(RMS quadratic bow, RMS scatter about it) of points about their best plane, m."""
    if len(xyz) < 6:
        return float("nan"), float("nan")
    centred = xyz - xyz.mean(axis=0)
    _u, _s, Vt = np.linalg.svd(centred, full_matrices=False)
    x, y, h = centred @ Vt[0], centred @ Vt[1], centred @ Vt[2]
    scale = max(float(np.abs(np.concatenate([x, y])).max()), 1e-12)
    x, y = x / scale, y / scale
    A = np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])
    coef = np.linalg.lstsq(A, h, rcond=None)[0]
    fit = A @ coef
    return float(np.sqrt(np.mean(fit ** 2))), float(np.sqrt(np.mean((h - fit) ** 2)))


def pad_rest_positions(target: PatternTarget, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """(N, 3) rest positions of cells in the pad frame (contract), m."""
    rows, cols = target.shape
    sx = -1.0 if target.mirrored else 1.0
    p = target.pitch_m
    return np.column_stack([sx * (np.asarray(col, float) - (cols - 1) / 2) * p,
                            (np.asarray(row, float) - (rows - 1) / 2) * p,
                            np.zeros(len(row))])


def _as_views(x: Glyphs | CameraView | Sequence[Glyphs | CameraView]) -> list[CameraView]:
    items = x if isinstance(x, Sequence) else [x]
    return [v if isinstance(v, CameraView) else CameraView.from_glyphs(v) for v in items]


def matched_cells(left: CameraView, right: CameraView, target: PatternTarget
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cells decoded in both images: rows, cols, left uv, right uv."""
    cl = target.cell_index(left.row, left.col)
    cr = target.cell_index(right.row, right.col)
    _c, a, b = np.intersect1d(cl, cr, return_indices=True)
    return left.row[a], left.col[a], left.uv[a], right.uv[b]


def calibration_health(left: Glyphs | CameraView | Sequence[Glyphs | CameraView],
                       right: Glyphs | CameraView | Sequence[Glyphs | CameraView],
                       rig: StereoRig, target: PatternTarget,
                       limits: HealthLimits | None = None) -> HealthReport:
    """Judge ``rig`` from decoded untouched frames (one or several: left[i] with right[i]).

    Glyphs must be decoded (row/col set).  Several frames of the untouched pad are pooled
    (the pad does not move), which averages the centroid noise.
    """
    lim = limits or HealthLimits()
    rows, cols, uvl, uvr = [], [], [], []
    for lv, rv in zip(_as_views(left), _as_views(right)):
        r, c, a, b = matched_cells(lv, rv, target)
        rows.append(r)
        cols.append(c)
        uvl.append(a)
        uvr.append(b)
    row = np.concatenate(rows) if rows else np.zeros(0, np.int32)
    col = np.concatenate(cols) if cols else np.zeros(0, np.int32)
    rep = HealthReport(len(row))
    swapped = (abs(rig.left.P[0, 3]) > 1e-12 and abs(rig.right.P[0, 3]) <= 1e-12)
    if swapped:
        rep.problems.append("the left calibration carries the baseline (its P[0,3] is not 0) "
                            "and the right one does not: left and right files are swapped")
    if len(row) < lim.min_points:
        rep.problems.append(f"only {len(row)} cells decoded in both images (need "
                            f"{lim.min_points}): is the pad in view, untouched, and the "
                            "pattern / mirrored setting right?")
        return rep
    rect_l = StereoRig.rectify(rig.left, np.concatenate(uvl))
    rect_r = StereoRig.rectify(rig.right, np.concatenate(uvr))
    x_rect, err = rig.triangulate_rectified(rect_l, rect_r)
    xyz = x_rect @ rig.left.R                      # physical left optical frame
    finite = np.isfinite(err) & np.isfinite(xyz).all(axis=1)
    rep.behind = int((~finite | (xyz[:, 2] <= 0)).sum())
    rep.reprojection_rms_px = float(np.sqrt(np.mean(err[finite] ** 2))) if finite.any() \
        else float("inf")
    rep.vertical_disparity_px = float(np.mean(rect_l[:, 1] - rect_r[:, 1]))
    rep.flatness_rms_m, rep.scatter_rms_m = _flatness(xyz[finite])
    s, R, t = similarity_fit(pad_rest_positions(target, row, col), xyz)
    rest = pad_rest_positions(target, row, col)
    rep.fit_rms_m = float(np.sqrt(np.mean(np.sum((xyz - (s * rest @ R.T + t)) ** 2, axis=1))))
    rep.pitch_error = s - 1.0
    rep.R_pad, rep.t_pad_m = R, t
    rep.tilt_deg = float(np.degrees(np.arccos(np.clip(abs(R[2, 2]), 0.0, 1.0))))
    if rep.behind > 0.05 * len(row):
        rep.problems.append(f"{100 * rep.behind / len(row):.0f} % of the pad triangulates "
                            "behind the cameras: left and right images or files swapped?")
    if not rep.reprojection_rms_px <= lim.max_reprojection_px:
        rep.problems.append(f"reprojection residual {rep.reprojection_rms_px:.3f} px > "
                            f"{lim.max_reprojection_px:g} px (a camera moved, or a wrong K/R)")
    if not rep.flatness_rms_m <= lim.max_flatness_m:
        rep.problems.append(f"pad flatness {rep.flatness_rms_m * 1e6:.2f} um > "
                            f"{lim.max_flatness_m * 1e6:g} um (distortion or intrinsics off)")
    if not abs(rep.pitch_error) <= lim.max_pitch_error:
        rep.problems.append(f"pitch error {100 * rep.pitch_error:+.3f} % beyond "
                            f"{100 * lim.max_pitch_error:g} % (baseline, focal length or "
                            "camera angle off)")
    return rep


def refine_extrinsics(views: list[StereoView], left: CameraCalibration,
                      right: CameraCalibration, target: PatternTarget,
                      min_cells: int = 50) -> StereoCalibrationResult:
    """Re-estimate R, T (and the rectification) from untouched frames, intrinsics fixed.

    The pad is the flat target (cells at (c * pitch, r * pitch, 0) of the artwork frame);
    the scale of T comes from the printed pitch.  ``cv2.stereoCalibrate`` with
    CALIB_FIX_INTRINSIC, then ``cv2.stereoRectify`` as in the full calibration.
    """
    objs, pts_l, pts_r = [], [], []
    for v in views:
        row, col, a, b = matched_cells(v.left, v.right, target)
        if len(row) >= min_cells:
            objs.append(target.object_points(row, col).astype(np.float32))
            pts_l.append(a.astype(np.float32).reshape(-1, 1, 2))
            pts_r.append(b.astype(np.float32).reshape(-1, 1, 2))
    if not objs:
        raise CalibrationError(f"no frame shows at least {min_cells} cells in both images; "
                               "cannot refine the extrinsics")
    size = (left.width, left.height)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    out = cv2.stereoCalibrate(objs, pts_l, pts_r, left.K, left.opencv_distortion(), right.K,
                              right.opencv_distortion(), size,
                              flags=cv2.CALIB_FIX_INTRINSIC, criteria=crit)
    rms, _k1, _d1, _k2, _d2, R, T = out[:7]
    R1, R2, P1, P2, *_ = cv2.stereoRectify(left.K, left.opencv_distortion(), right.K,
                                           right.opencv_distortion(), size, R,
                                           T.reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY,
                                           alpha=0.0)
    new_l = CameraCalibration(size[0], size[1], left.K, left.D, R1, P1,
                              camera_name=left.camera_name)
    new_r = CameraCalibration(size[0], size[1], right.K, right.D, R2, P2,
                              camera_name=right.camera_name)
    return StereoCalibrationResult(new_l, new_r, np.asarray(R), np.asarray(T).reshape(3),
                                   float(rms), float("nan"), float("nan"), len(objs),
                                   len(views))
