"""Stereo calibration from decoded views of the printed pattern (Zhang's method via OpenCV).

Every decoded cell is a uniquely identified point of a flat target, so views may be partial
or occluded (as with ChArUco boards).  Steps:

1. per view and camera, at least ``min_cells`` decoded cells, and a homography that maps the
   artwork plane onto at least ``min_inlier_ratio`` of them (RANSAC, cv2.findHomography):
   otherwise the view is skipped with the reason (another pattern, a wrong ``mirrored``);
2. per camera, Zhang's method [Zhang 2000, "A flexible new technique for camera
   calibration", IEEE TPAMI 22(11)] through ``cv2.calibrateCameraExtended`` (plumb-bob
   distortion, k3 fixed at 0 by default as ROS camera_calibration does); points whose
   reprojection error exceeds ``max(outlier_floor_px, outlier_sigmas * 1.4826 * MAD)`` are
   dropped and the camera recalibrated (a glyph cut by an occluder's edge, a split glyph);
3. degenerate sets are refused: every view plane nearly parallel (Zhang's method needs
   planes of different orientations: section 3.3 of the paper), or the focal length
   undetermined (its standard deviation over ``max_focal_std``);
4. ``cv2.stereoCalibrateExtended`` on the cells seen by both cameras (intrinsics refined
   jointly, or fixed), then ``cv2.stereoRectify`` (zero disparity, alpha 0) for the ROS
   stereo R and P, as the checkerboard path does.

Units: metres and pixels.  R, T map the left optical frame into the right one
(x_r = R x_l + T).
"""
from __future__ import annotations

import os
import pathlib
from dataclasses import dataclass, field

import cv2
import numpy as np

from tactile_sl_common.camera_info import CameraCalibration, camera_info_yaml_text
from tactile_sl_common.safe_files import write_files
from tactile_sl_decoder.calibrate.result import CalibrationError, StereoCalibrationResult

from .views import CameraView, PatternTarget, StereoView

CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)


@dataclass
class CalibrationOptions:
    """Thresholds of the pattern-target calibration (pixels, degrees, counts)."""

    min_cells: int = 30            # decoded cells a view needs in a camera to be used
    min_views: int = 4             # usable views per camera (Zhang: >= 3 for K + distortion)
    min_inlier_ratio: float = 0.8  # share of a view's cells on one plane (homography)
    ransac_spacings: float = 0.5   # homography inlier radius, in glyph spacings
    outlier_floor_px: float = 0.3  # never drop points closer than this
    outlier_sigmas: float = 5.0    # robust sigmas (1.4826 MAD) beyond which a point is dropped
    outlier_rounds: int = 3
    min_tilt_spread_deg: float = 8.0   # largest angle between two view planes, at least
    max_focal_std: float = 0.005   # relative standard deviation of fx, fy at most
    fix_k3: bool = True
    fix_intrinsics: bool = False   # stereo step: keep each camera's own intrinsics


@dataclass
class ViewReport:
    """What one stereo view contributed."""

    name: str
    cells_left: int
    cells_right: int
    cells_stereo: int = 0          # cells used in the stereo step (both cameras, inliers)
    dropped_left: int = 0          # outliers dropped (homography or reprojection)
    dropped_right: int = 0
    rms_left: float = float("nan")   # reprojection RMS, px (per-camera calibration)
    rms_right: float = float("nan")
    rms_stereo: float = float("nan")
    skipped: str = ""              # reason, if the view was not used at all

    def line(self) -> str:
        """One report line."""
        head = (f"view {self.name}: cells L {self.cells_left:4d} R {self.cells_right:4d}")
        if self.skipped:
            return f"{head}  skipped: {self.skipped}"
        return (f"{head} stereo {self.cells_stereo:4d}  dropped L {self.dropped_left} "
                f"R {self.dropped_right}  RMS L {self.rms_left:.3f} R {self.rms_right:.3f} "
                f"stereo {self.rms_stereo:.3f} px")


@dataclass
class PatternCalibration:
    """Result of a pattern-target calibration with its per-view report and coverage."""

    result: StereoCalibrationResult
    views: list[ViewReport]
    points_left: np.ndarray        # (N, 2) image points used, px (for the coverage picture)
    points_right: np.ndarray
    tilt_spread_deg: float = 0.0
    std_focal: tuple[float, float] = (0.0, 0.0)   # relative std of fx (left, right)
    options: CalibrationOptions = field(default_factory=CalibrationOptions)

    @property
    def left(self) -> CameraCalibration:
        return self.result.left

    @property
    def right(self) -> CameraCalibration:
        return self.result.right

    def summary(self) -> str:
        """Quality figures in two lines."""
        return (f"{self.result.summary()}\nview planes span {self.tilt_spread_deg:.1f} deg; "
                f"focal std L {100 * self.std_focal[0]:.3f} % R {100 * self.std_focal[1]:.3f} %;"
                f" image covered L {100 * coverage_fraction(self.points_left, self.left):.0f} %"
                f" R {100 * coverage_fraction(self.points_right, self.right):.0f} %")

    def report(self) -> str:
        """Per-view report, one line per view."""
        return "\n".join(v.line() for v in self.views)

    def save(self, directory: str | os.PathLike, coverage: bool = True
             ) -> list[pathlib.Path]:
        """Write left.yaml, right.yaml (and coverage.png), all or none; returns the paths."""
        files: dict[str, bytes] = {
            "left.yaml": camera_info_yaml_text(self.left).encode(),
            "right.yaml": camera_info_yaml_text(self.right).encode()}
        if coverage:
            ok, png = cv2.imencode(".png", coverage_image(self))
            if ok:
                files["coverage.png"] = png.tobytes()
        return write_files(directory, files)


# --------------------------------------------------------------------------- per camera


def _plane_inliers(view: CameraView, target: PatternTarget, opts: CalibrationOptions
                   ) -> np.ndarray | None:
    """Cells consistent with one plane (homography, RANSAC); None if there are too few."""
    obj = target.object_points(view.row, view.col)[:, :2]
    spacing = view.spacing_px if view.spacing_px > 0 else 15.0
    H, mask = cv2.findHomography(obj, view.uv, cv2.RANSAC,
                                 max(2.0, opts.ransac_spacings * spacing), maxIters=2000,
                                 confidence=0.999)
    if H is None or mask is None:
        return None
    return mask.reshape(-1).astype(bool)


def _residuals(obj: list[np.ndarray], img: list[np.ndarray], K: np.ndarray, D: np.ndarray,
               rvecs: list[np.ndarray], tvecs: list[np.ndarray]) -> list[np.ndarray]:
    """Per view, the reprojection error (px) of every point."""
    out = []
    for o, i, r, t in zip(obj, img, rvecs, tvecs):
        p, _ = cv2.projectPoints(o, r, t, K, D)
        out.append(np.linalg.norm(p.reshape(-1, 2) - i.reshape(-1, 2), axis=1))
    return out


@dataclass
class _CameraFit:
    K: np.ndarray
    D: np.ndarray
    rms: float
    rvecs: list[np.ndarray]
    tvecs: list[np.ndarray]
    std: np.ndarray
    keep: list[np.ndarray]          # per used view, mask over that view's cells
    per_view_rms: np.ndarray


def _calibrate_camera(obj_all: list[np.ndarray], img_all: list[np.ndarray],
                      size: tuple[int, int], opts: CalibrationOptions, side: str) -> _CameraFit:
    """Zhang's method with robust reprojection-outlier rejection (a few rounds)."""
    flags = cv2.CALIB_FIX_K3 if opts.fix_k3 else 0
    keep = [np.ones(len(o), bool) for o in obj_all]
    for round_ in range(opts.outlier_rounds + 1):
        obj = [o[k].astype(np.float32) for o, k in zip(obj_all, keep)]
        img = [i[k].astype(np.float32).reshape(-1, 1, 2) for i, k in zip(img_all, keep)]
        try:
            # cv2's stub requires arrays for K and D; None makes OpenCV allocate them (its
            # stub for calibrateCamera allows None for the same output arguments)
            rms, K, D, rvecs, tvecs, std, _se, per_view = cv2.calibrateCameraExtended(
                obj, img, size, None, None, flags=flags,  # type: ignore[call-overload]
                criteria=CRITERIA)
        except cv2.error as exc:
            raise CalibrationError(
                f"{side} camera: OpenCV could not calibrate ({exc.err}); the views are "
                "probably degenerate (all planes parallel): tilt the target in several "
                "directions") from None
        if round_ == opts.outlier_rounds:
            break
        res = _residuals([o[k] for o, k in zip(obj_all, keep)],
                         [i[k] for i, k in zip(img_all, keep)], K, D, rvecs, tvecs)
        flat = np.concatenate(res)
        mad = float(np.median(np.abs(flat - np.median(flat))))
        limit = max(opts.outlier_floor_px, opts.outlier_sigmas * 1.4826 * mad)
        changed = False
        for k, r in zip(keep, res):
            bad = r > limit
            if bad.any():
                idx = np.flatnonzero(k)[bad]
                k[idx] = False
                changed = True
        if not changed:
            break
    return _CameraFit(K, D.reshape(-1), float(rms), list(rvecs), list(tvecs),
                      std.reshape(-1), keep, per_view.reshape(-1))


def _tilt_spread_deg(rvecs: list[np.ndarray]) -> float:
    """Largest angle between two view planes' normals (deg) from the views' rotations."""
    normals = np.array([cv2.Rodrigues(r)[0][:, 2] for r in rvecs])
    cos = np.clip(np.abs(normals @ normals.T), 0.0, 1.0)
    return float(np.degrees(np.arccos(cos.min())))


# --------------------------------------------------------------------------- stereo


def _usable_views(views: list[StereoView], target: PatternTarget, opts: CalibrationOptions,
                  reports: list[ViewReport]
                  ) -> tuple[dict[str, list[int]], dict[str, dict[int, np.ndarray]]]:
    """Per camera, the views with enough cells on one plane and those cells' masks.

    Fills ``reports[i].skipped`` for views neither camera can use; raises when a camera has
    fewer than ``opts.min_views``.
    """
    usable: dict[str, list[int]] = {"left": [], "right": []}
    masks: dict[str, dict[int, np.ndarray]] = {"left": {}, "right": {}}
    reasons: dict[int, list[str]] = {}
    for i, v in enumerate(views):
        for side in ("left", "right"):
            cam: CameraView = getattr(v, side)
            if len(cam) < opts.min_cells:
                reasons.setdefault(i, []).append(
                    f"{side}: {len(cam)} cells decoded (< {opts.min_cells}): "
                    f"{cam.why_few_cells()}")
                continue
            inl = _plane_inliers(cam, target, opts)
            ratio = float(inl.mean()) if inl is not None else 0.0
            if inl is None or ratio < opts.min_inlier_ratio:
                reasons.setdefault(i, []).append(
                    f"{side}: only {100 * ratio:.0f} % of the cells lie on one plane "
                    "(not this pattern, or a wrong mirrored setting?)")
                continue
            usable[side].append(i)
            masks[side][i] = inl
    for i, r in enumerate(reports):
        if i not in usable["left"] and i not in usable["right"]:
            r.skipped = "; ".join(reasons.get(i, ["no cells"]))
    best = max((max(len(v.left), len(v.right)) for v in views), default=0)
    for side in ("left", "right"):
        n = len(usable[side])
        if n < opts.min_views:
            hint = ""
            if n == 0:
                hint = (f" (at most {best} cells decoded in any image: are these views of "
                        f"this pattern, {target.shape[0]}x{target.shape[1]} cells, with "
                        f"mirrored={'true' if target.mirrored else 'false'}?)")
            raise CalibrationError(
                f"only {n} of {len(views)} views are usable in the {side} camera; need at "
                f"least {opts.min_views}{hint}")
    return usable, masks


def _check_poses(fits: dict[str, _CameraFit], opts: CalibrationOptions
                 ) -> tuple[float, tuple[float, float]]:
    """(tilt spread in deg, relative focal std per camera); raises for degenerate poses."""
    spread = min(_tilt_spread_deg(fits[s].rvecs) for s in ("left", "right"))
    if spread < opts.min_tilt_spread_deg:
        raise CalibrationError(
            f"degenerate views: all view planes lie within {spread:.1f} deg of each other "
            f"(need at least {opts.min_tilt_spread_deg:g}): Zhang's method needs the target "
            "tilted in several directions (e.g. 20-35 deg left, right, up and down)")
    std_f = tuple(float(max(fits[s].std[0] / fits[s].K[0, 0], fits[s].std[1] / fits[s].K[1, 1]))
                  for s in ("left", "right"))
    if max(std_f) > opts.max_focal_std:
        raise CalibrationError(
            f"degenerate views: the focal length is undetermined (std {100 * max(std_f):.2f} "
            f"% > {100 * opts.max_focal_std:.2f} %); add views tilted in other directions")
    return spread, (std_f[0], std_f[1])


def calibrate_pattern_stereo(views: list[StereoView], target: PatternTarget,
                             options: CalibrationOptions | None = None
                             ) -> PatternCalibration:
    """Calibrate the stereo pair from decoded views of the pattern; CalibrationError if not.

    Views with too few cells or cells off one plane are skipped and reported.  Raises for too
    few usable views, a degenerate set of poses, or views of mixed image sizes.
    """
    opts = options or CalibrationOptions()
    if not views:
        raise CalibrationError("no image pairs")
    size = views[0].image_size
    for v in views:
        if v.image_size != size:
            raise CalibrationError(f"view {v.name}: image size {v.image_size[0]}x"
                                   f"{v.image_size[1]} differs from the first view's "
                                   f"{size[0]}x{size[1]}")
    reports = [ViewReport(v.name, len(v.left), len(v.right)) for v in views]
    # 1. per camera: enough cells, one plane
    usable, masks = _usable_views(views, target, opts, reports)
    # 2. each camera on its own
    fits: dict[str, _CameraFit] = {}
    for side in ("left", "right"):
        obj, img = [], []
        for i in usable[side]:
            cam = getattr(views[i], side)
            m = masks[side][i]
            obj.append(target.object_points(cam.row[m], cam.col[m]))
            img.append(cam.uv[m])
        fits[side] = fit = _calibrate_camera(obj, img, size, opts, side)
        for j, i in enumerate(usable[side]):
            m = masks[side][i]
            setattr(reports[i], f"dropped_{side}", int((~m).sum() + (~fit.keep[j]).sum()))
            setattr(reports[i], f"rms_{side}", float(fit.per_view_rms[j]))
    # 3. degeneracy
    spread, std_f = _check_poses(fits, opts)
    # 4. stereo on the cells both cameras kept
    objs, pts_l, pts_r, stereo_ids = [], [], [], []
    for i, v in enumerate(views):
        if i not in masks["left"] or i not in masks["right"]:
            continue
        kl = np.zeros(len(v.left), bool)
        kl[np.flatnonzero(masks["left"][i])[fits["left"].keep[usable["left"].index(i)]]] = True
        kr = np.zeros(len(v.right), bool)
        kr[np.flatnonzero(masks["right"][i])[fits["right"].keep[usable["right"].index(i)]]] = \
            True
        cl = target.cell_index(v.left.row, v.left.col)
        cr = target.cell_index(v.right.row, v.right.col)
        il, ir = np.flatnonzero(kl), np.flatnonzero(kr)
        _common, a, b = np.intersect1d(cl[il], cr[ir], assume_unique=True,
                                       return_indices=True)
        il, ir = il[a], ir[b]
        reports[i].cells_stereo = len(il)
        if len(il) < opts.min_cells:
            continue
        objs.append(target.object_points(v.left.row[il], v.left.col[il]).astype(np.float32))
        pts_l.append(v.left.uv[il].astype(np.float32).reshape(-1, 1, 2))
        pts_r.append(v.right.uv[ir].astype(np.float32).reshape(-1, 1, 2))
        stereo_ids.append(i)
    if len(objs) < 2:
        raise CalibrationError(f"only {len(objs)} views show at least {opts.min_cells} "
                               "cells in both cameras; need 2 for the stereo extrinsics")
    fl, fr = fits["left"], fits["right"]
    flags = cv2.CALIB_FIX_INTRINSIC if opts.fix_intrinsics else cv2.CALIB_USE_INTRINSIC_GUESS
    if opts.fix_k3:
        flags |= cv2.CALIB_FIX_K3
    out = cv2.stereoCalibrateExtended(objs, pts_l, pts_r, fl.K.copy(), fl.D.copy(),
                                      fr.K.copy(), fr.D.copy(), size, np.eye(3),
                                      np.zeros((3, 1)), flags=flags, criteria=CRITERIA)
    rms, K1, D1, K2, D2, R, T = out[:7]
    per_view = np.asarray(out[11]).reshape(len(objs), -1)
    for j, i in enumerate(stereo_ids):
        reports[i].rms_stereo = float(np.sqrt(np.mean(per_view[j] ** 2)))
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K1, D1, K2, D2, size, R, T.reshape(3, 1),
                                           flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0)
    left = CameraCalibration(size[0], size[1], K1, D1.reshape(-1)[:5], R1, P1,
                             camera_name="tactile_left")
    right = CameraCalibration(size[0], size[1], K2, D2.reshape(-1)[:5], R2, P2,
                              camera_name="tactile_right")
    result = StereoCalibrationResult(left, right, np.asarray(R), np.asarray(T).reshape(3),
                                     float(rms), fl.rms, fr.rms, len(objs), len(views))
    return PatternCalibration(result, reports, np.concatenate([p.reshape(-1, 2) for p in pts_l]),
                              np.concatenate([p.reshape(-1, 2) for p in pts_r]), spread,
                              std_f, opts)


# --------------------------------------------------------------------------- coverage


def coverage_fraction(points: np.ndarray, cam: CameraCalibration, bins: tuple[int, int] = (16, 12)
                      ) -> float:
    """Share of a bins[0] x bins[1] grid over the image holding at least one point."""
    if len(points) == 0:
        return 0.0
    h, _, _ = np.histogram2d(points[:, 0], points[:, 1], bins=bins,
                             range=[[0, cam.width], [0, cam.height]])
    return float((h > 0).mean())


def coverage_image(cal: PatternCalibration, scale: float = 0.5, bins: tuple[int, int] = (16, 12)
                   ) -> np.ndarray:
    """BGR picture of where the used image points lie, left and right side by side.

    Point density is colour-mapped; grid cells of the image without any point are outlined
    in red so that the user sees which poses are still missing.
    """
    panels = []
    for side, pts, cam in (("left", cal.points_left, cal.left), ("right", cal.points_right,
                                                                 cal.right)):
        w, h = int(round(cam.width * scale)), int(round(cam.height * scale))
        acc: np.ndarray = np.zeros((h, w), np.float32)
        if len(pts):
            xy = np.clip(np.rint(pts * scale).astype(np.int64), 0, [w - 1, h - 1])
            np.add.at(acc, (xy[:, 1], xy[:, 0]), 1.0)
        acc = cv2.GaussianBlur(acc, (0, 0), 3.0)
        norm = (255 * np.sqrt(acc / max(float(acc.max()), 1e-9))).astype(np.uint8)
        img = cv2.applyColorMap(norm, cv2.COLORMAP_VIRIDIS)
        img[acc <= 0] = (40, 40, 40)
        hist = np.histogram2d(pts[:, 0], pts[:, 1], bins=bins,
                              range=[[0, cam.width], [0, cam.height]])[0] if len(pts) else \
            np.zeros(bins)
        bw, bh = w / bins[0], h / bins[1]
        for bx, by in np.argwhere(hist == 0):
            cv2.rectangle(img, (int(bx * bw) + 1, int(by * bh) + 1),
                          (int((bx + 1) * bw) - 2, int((by + 1) * bh) - 2), (0, 0, 255), 1)
        cv2.putText(img, f"{side}: {len(pts)} points, {100 * coverage_fraction(pts, cam):.0f} %"
                    " of the image", (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255),
                    1, cv2.LINE_AA)
        panels.append(img)
    gap = np.full((panels[0].shape[0], 6, 3), 255, np.uint8)
    return np.hstack([panels[0], gap, panels[1]])
