"""Stereo checkerboard calibration (Zhang's method through OpenCV) into ROS camera_info files.

Pipeline: find the inner corners of a checkerboard in every image pair (refined to sub-pixel),
calibrate each camera (K, plumb-bob D with k3 fixed at 0 by default, like ROS's
camera_calibration), refine both jointly with the extrinsics (``cv2.stereoCalibrate``), then
rectify (``cv2.stereoRectify``, zero disparity at infinity) to get the R and P that the ROS
stereo convention publishes. Inputs are image pairs from a folder or from a bag.
"""
from __future__ import annotations

import os
import pathlib
from typing import Callable, Iterable, Iterator

import cv2
import numpy as np

from tactile_sl_common.bag_io import BagReader
from tactile_sl_common.camera_info import CameraCalibration
from tactile_sl_common.images import to_gray
from tactile_sl_decoder.calibrate.result import CalibrationError, StereoCalibrationResult

SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")


def board_points(pattern: tuple[int, int], square: float) -> np.ndarray:
    """3-D inner-corner positions (cols x rows, row-major as OpenCV reports them), z = 0."""
    cols, rows = pattern
    grid = np.zeros((rows * cols, 3), np.float32)
    grid[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square
    return grid


def find_corners(gray: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners (N, 1, 2) float32 of a checkerboard, or None if not found."""
    if gray.ndim == 3:
        gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, pattern, flags=flags)
    if not found:
        return None
    # refine window ~ a third of the smallest corner spacing
    c = corners.reshape(-1, 2)
    spacing = np.min(np.linalg.norm(np.diff(c.reshape(pattern[1], pattern[0], 2), axis=1),
                                    axis=2))
    win = int(np.clip(spacing / 3, 2, 11))
    corners = cv2.cornerSubPix(gray, corners, (win, win), (-1, -1), SUBPIX_CRITERIA)
    return corners.astype(np.float32)


def calibrate_stereo(pairs: Iterable[tuple[np.ndarray, np.ndarray]], pattern: tuple[int, int],
                     square: float, fix_k3: bool = True, min_pairs: int = 5,
                     on_pair: Callable[[int, bool], None] | None = None
                     ) -> StereoCalibrationResult:
    """Calibrate a stereo pair from checkerboard image pairs (grey or BGR arrays)."""
    if square <= 0:
        raise CalibrationError("square size must be positive (metres)")
    obj = board_points(pattern, square)
    objs, left_pts, right_pts = [], [], []
    size = None
    total = 0
    for i, (left, right) in enumerate(pairs):
        total += 1
        if left.shape[:2] != right.shape[:2]:
            raise CalibrationError(f"pair {i}: left and right images differ in size")
        if size is None:
            size = (left.shape[1], left.shape[0])
        elif size != (left.shape[1], left.shape[0]):
            raise CalibrationError(f"pair {i}: image size {left.shape[1]}x{left.shape[0]} "
                                   f"differs from the first pair's {size[0]}x{size[1]}")
        cl, cr = find_corners(left, pattern), find_corners(right, pattern)
        if cl is not None and cr is not None:
            objs.append(obj)
            left_pts.append(cl)
            right_pts.append(cr)
        if on_pair:
            on_pair(i, cl is not None and cr is not None)
    if size is None:
        raise CalibrationError("no image pairs")
    if len(objs) < min_pairs:
        raise CalibrationError(f"the {pattern[0]}x{pattern[1]} checkerboard was found in both "
                               f"images of only {len(objs)} of {total} pairs; need at least "
                               f"{min_pairs} (check --pattern: inner corners, columns x rows)")
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    rms_l, K1, D1, _, _ = cv2.calibrateCamera(objs, left_pts, size, None, None, flags=flags,
                                              criteria=crit)
    rms_r, K2, D2, _, _ = cv2.calibrateCamera(objs, right_pts, size, None, None, flags=flags,
                                              criteria=crit)
    out = cv2.stereoCalibrate(objs, left_pts, right_pts, K1, D1, K2, D2, size,
                              flags=flags | cv2.CALIB_USE_INTRINSIC_GUESS, criteria=crit)
    rms, K1, D1, K2, D2, R, T = out[:7]
    R1, R2, P1, P2, _Q, _a, _b = cv2.stereoRectify(K1, D1, K2, D2, size, R, T.reshape(3, 1),
                                                   flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0)
    left_calib = CameraCalibration(size[0], size[1], K1, D1.reshape(-1)[:5], R1, P1,
                                   camera_name="tactile_left")
    right_calib = CameraCalibration(size[0], size[1], K2, D2.reshape(-1)[:5], R2, P2,
                                    camera_name="tactile_right")
    return StereoCalibrationResult(left_calib, right_calib, np.asarray(R), np.asarray(T).reshape(3),
                                   float(rms), float(rms_l), float(rms_r), len(objs), total)


# --------------------------------------------------------------------------- inputs


def _read(path: pathlib.Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise CalibrationError(f"{path}: not a readable image")
    return image


def _folder_images(folder: str | os.PathLike) -> dict[str, pathlib.Path]:
    d = pathlib.Path(folder)
    if not d.is_dir():
        raise CalibrationError(f"{d}: not a folder")
    return {p.name: p for p in d.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES}


def unpaired_images(folder: str | os.PathLike) -> list[pathlib.Path]:
    """Images named for one camera ('left' or 'right') whose twin is missing: not used."""
    files = _folder_images(folder)
    return [files[name] for name in sorted(files)
            if ("left" in name and name.replace("left", "right") not in files)
            or ("right" in name and "left" not in name
                and name.replace("right", "left") not in files)]


def folder_pairs(folder: str | os.PathLike) -> list[tuple[pathlib.Path, pathlib.Path]]:
    """Image pairs in a folder: every file with 'left' in its name and its 'right' twin.

    Images without a twin are left out; :func:`unpaired_images` names them.
    """
    d = pathlib.Path(folder)
    files = _folder_images(d)
    pairs = []
    for name in sorted(files):
        if "left" in name:
            twin = name.replace("left", "right")
            if twin in files:
                pairs.append((files[name], files[twin]))
    if not pairs:
        raise CalibrationError(f"{d}: no image pairs (expected names like left_000.png and "
                               "right_000.png)")
    return pairs


def iter_folder_pairs(folder: str | os.PathLike) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    for left, right in folder_pairs(folder):
        yield _read(left), _read(right)


def iter_bag_pairs(path: str | os.PathLike, left_topic: str = "/tactile/left/image_raw",
                   right_topic: str = "/tactile/right/image_raw", every: int = 1
                   ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Image pairs of a bag, paired by exactly equal header stamps."""
    reader = BagReader(path)
    reader.require_topics([left_topic, right_topic])
    pending: dict[tuple[int, int], dict[str, np.ndarray]] = {}
    count = 0
    for raw, msg in reader.messages([left_topic, right_topic]):
        stamp = (int(msg.header.stamp.sec), int(msg.header.stamp.nanosec))
        slot = pending.setdefault(stamp, {})
        slot[raw.topic] = to_gray(msg).copy()
        if len(slot) == 2:
            del pending[stamp]
            if count % max(1, every) == 0:
                yield slot[left_topic], slot[right_topic]
            count += 1
        for old in [s for s in pending if s < stamp][:-50]:  # drop unmatched old frames
            del pending[old]
