"""Extraction and classification figures against a bag's ground truth (no rclpy).

The ground truth (``/tactile/ground_truth/points``: true 3-D cell centres of every glyph
visible in both images, physical left optical frame) is projected into each raw image with
its CameraInfo (left: K, D; right: through the rectified frames, X_r = R_r^T (R_l X - B e_x),
then K_r, D_r). Per image:

* **recall**: true glyphs with a detection within a quarter of the spacing;
* **spurious rate**: detections within the ground truth's region (convex hull of the true
  centres, grown by half a spacing) farther than a quarter spacing from every true centre,
  over all detections in that region; detections outside the region (glyphs seen by one
  camera only, image margins) are counted apart as ``outside``;
* **classification**: each true glyph matched one-to-one with its nearest detection; the
  true label is the pattern's value at its cell. ``accuracy`` counts unknown (255) labels
  as wrong; ``confident accuracy`` ignores them; a confusion matrix (true x predicted, last
  column = unknown).

Each report section is a function returning plain dicts; ``format_*`` turn them into text
tables, so later sections (end-to-end figures) can join the same report.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import cv2
import numpy as np
from scipy.spatial import cKDTree

from tactile_sl_common.camera_info import CameraInfoError, calibration_from_msg, stereo_baseline
from tactile_sl_common.clouds import cloud_to_arrays
from tactile_sl_common.images import ImageFormatError, to_gray
from tactile_sl_decoder.contract import LABEL_UNKNOWN
from tactile_sl_decoder.extract.extraction import ExtractionParams, extract_symbols
from tactile_sl_decoder.frames import bag_frames, count_bag_frames
from tactile_sl_decoder.glyphs import PipelineInputError
from tactile_sl_decoder.pipeline import check_image


@dataclass
class ImageSymbolMetrics:
    """Figures of one camera image."""

    scene: str
    frame: int
    camera: str
    truth: int = 0
    detections: int = 0
    found: int = 0
    in_region: int = 0
    spurious: int = 0
    outside: int = 0
    matched: int = 0
    correct: int = 0
    unknown: int = 0
    confusion: list[list[int]] = field(default_factory=list)
    extract_ms: float = 0.0
    classify_ms: float = 0.0

    @property
    def recall(self) -> float:
        """Found / true glyphs."""
        return self.found / self.truth if self.truth else float("nan")

    @property
    def spurious_rate(self) -> float:
        """Spurious / detections in the ground-truth region."""
        return self.spurious / self.in_region if self.in_region else 0.0

    @property
    def accuracy(self) -> float:
        """Correct labels / matched glyphs (unknown counts as wrong)."""
        return self.correct / self.matched if self.matched else float("nan")

    @property
    def confident_accuracy(self) -> float:
        """Correct labels / matched glyphs with a label."""
        sure = self.matched - self.unknown
        return self.correct / sure if sure else float("nan")


def project_truth(xyz: np.ndarray, left: Any, right: Any) -> tuple[np.ndarray, np.ndarray]:
    """Raw pixel positions (N, 2) of 3-D points (left optical frame) in both cameras."""
    xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
    if len(xyz) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    zero = np.zeros(3)
    pl, _ = cv2.projectPoints(xyz, zero, zero, left.K, left.opencv_distortion())
    rect = xyz @ left.R.T
    rect[:, 0] -= stereo_baseline(left, right)
    xr = rect @ right.R  # R_r^T applied to row vectors
    pr, _ = cv2.projectPoints(xr, zero, zero, right.K, right.opencv_distortion())
    return pl.reshape(-1, 2), pr.reshape(-1, 2)


def score_image(u: np.ndarray, v: np.ndarray, spacing: float, truth_px: np.ndarray,
                truth_labels: np.ndarray | None, labels: np.ndarray | None,
                image_shape: tuple[int, int], classes: int, out: ImageSymbolMetrics) -> None:
    """Fill ``out`` with the matching figures of one image's detections."""
    tol = 0.25 * (spacing if spacing > 0 else 18.0)
    out.truth, out.detections = len(truth_px), len(u)
    det = np.column_stack((u, v)).astype(np.float64)
    out.confusion = np.zeros((classes, classes + 1), np.int64).tolist()
    if len(truth_px) == 0:
        out.outside = len(u)
        return
    if len(u) == 0:
        return
    dist_t, _ = cKDTree(det).query(truth_px)
    out.found = int((dist_t < tol).sum())
    # ground-truth region: convex hull of the true centres, grown by half a spacing
    h, w = image_shape
    region: np.ndarray = np.zeros((h, w), np.uint8)
    hull = cv2.convexHull(np.round(truth_px).astype(np.int32))
    cv2.fillConvexPoly(region, hull, 255)
    grow = max(1, int(round(0.5 * (spacing if spacing > 0 else 18.0))))
    region = cv2.dilate(region, np.ones((2 * grow + 1, 2 * grow + 1), np.uint8))
    iu = np.clip(np.round(u).astype(int), 0, w - 1)
    iv = np.clip(np.round(v).astype(int), 0, h - 1)
    inside = region[iv, iu] > 0
    dist_d, nearest = cKDTree(truth_px).query(det)
    out.in_region = int(inside.sum())
    out.outside = int((~inside).sum())
    out.spurious = int((inside & (dist_d >= tol)).sum())
    if labels is None or truth_labels is None:
        return
    # one-to-one: each detection claims its nearest true glyph; the nearest claim wins
    ok = np.flatnonzero(dist_d < tol)
    order = ok[np.argsort(dist_d[ok])]
    _, first = np.unique(nearest[order], return_index=True)
    chosen = order[first]
    t = truth_labels[nearest[chosen]].astype(np.int64)
    p = labels[chosen].astype(np.int64)
    p_col = np.where(p == LABEL_UNKNOWN, classes, np.minimum(p, classes))
    conf = np.zeros((classes, classes + 1), np.int64)
    valid = t < classes
    np.add.at(conf, (t[valid], p_col[valid]), 1)
    out.confusion = conf.tolist()
    out.matched = int(valid.sum())
    out.correct = int((p[valid] == t[valid]).sum())
    out.unknown = int((p[valid] == LABEL_UNKNOWN).sum())


SkipCallback = Callable[[int, str], None]
"""``on_skip(stamp_ns, why)``: a frame left out of an evaluation because its input is bad."""


FRAME_INPUT_ERRORS: tuple[type[Exception], ...] = (ImageFormatError, CameraInfoError,
                                                    PipelineInputError)
"""What a frame's unusable input raises (image encoding or size, CameraInfo): the frame is
skipped with a warning, as ``tactile-sl replay`` does."""


def frame_input(frame: Any) -> tuple[Any, Any, tuple[np.ndarray, np.ndarray]]:
    """(left, right calibration, (left, right grey image)) of a bag frame, checked.

    Raises one of :data:`FRAME_INPUT_ERRORS` for an image the project cannot read (mono16,
    yuv422, ...), one whose size is not its CameraInfo's, or a missing or bad CameraInfo.
    """
    if frame.left_info is None or frame.right_info is None:
        raise CameraInfoError("no camera_info for this frame")
    left = calibration_from_msg(frame.left_info, "left CameraInfo")
    right = calibration_from_msg(frame.right_info, "right CameraInfo")
    grays = (to_gray(frame.left_image), to_gray(frame.right_image))
    check_image(grays[0], left, "left")
    check_image(grays[1], right, "right")
    return left, right, grays


def evaluate_symbols_bag(path: str | Path, values: np.ndarray, classifier: Any,
                         params: ExtractionParams | None = None, namespace: str = "/tactile",
                         progress: Callable[[int, int], None] | None = None,
                         max_frames: int = 0, on_skip: SkipCallback | None = None
                         ) -> list[ImageSymbolMetrics]:
    """Per-image extraction and classification figures of every frame with ground truth.

    A frame whose images or CameraInfo cannot be used (encoding, size against the
    CameraInfo, calibration) is passed to ``on_skip(stamp_ns, why)`` and left out; without
    ``on_skip`` the error is raised (see :data:`FRAME_INPUT_ERRORS`).
    """
    scene = Path(path).stem
    total = count_bag_frames(path, namespace)
    rows: list[ImageSymbolMetrics] = []
    classes = int(classifier.classes) if classifier is not None else int(values.max()) + 1
    for i, frame in enumerate(bag_frames(path, namespace)):
        if max_frames and i >= max_frames:
            break
        if progress:
            progress(i + 1, total)
        if frame.ground_truth is None:
            continue
        try:
            left, right, grays = frame_input(frame)
        except FRAME_INPUT_ERRORS as exc:
            if on_skip is None:
                raise
            on_skip(frame.stamp_ns, str(exc))
            continue
        truth = cloud_to_arrays(frame.ground_truth)
        xyz = np.column_stack((truth["x"], truth["y"], truth["z"]))
        px = project_truth(xyz, left, right)
        r, c = truth["row"].astype(np.int64), truth["col"].astype(np.int64)
        inside = (r >= 0) & (r < values.shape[0]) & (c >= 0) & (c < values.shape[1])
        labels_true = np.full(len(r), LABEL_UNKNOWN, np.uint8)
        labels_true[inside] = values[r[inside], c[inside]]
        for camera, gray, tpx in (("left", grays[0], px[0]), ("right", grays[1], px[1])):
            m = ImageSymbolMetrics(scene, i, camera)
            start = time.perf_counter()
            det = extract_symbols(gray, params)
            m.extract_ms = 1000 * (time.perf_counter() - start)
            labels = None
            if classifier is not None:
                start = time.perf_counter()
                labels, _ = classifier.predict(det.patches)
                m.classify_ms = 1000 * (time.perf_counter() - start)
            score_image(det.u, det.v, det.spacing_px, tpx, labels_true, labels, gray.shape,
                        classes, m)
            rows.append(m)
    return rows


def aggregate(rows: list[ImageSymbolMetrics], scene: str = "") -> ImageSymbolMetrics:
    """Sum of several images' counts (frame -1, camera 'both')."""
    total = ImageSymbolMetrics(scene or (rows[0].scene if rows else ""), -1, "both")
    conf = None
    for r in rows:
        for key in ("truth", "detections", "found", "in_region", "spurious", "outside",
                    "matched", "correct", "unknown"):
            setattr(total, key, getattr(total, key) + getattr(r, key))
        c = np.asarray(r.confusion)
        conf = c if conf is None else (conf + c if c.shape == conf.shape else conf)
    total.confusion = conf.tolist() if conf is not None else []
    total.extract_ms = float(np.median([r.extract_ms for r in rows])) if rows else 0.0
    total.classify_ms = float(np.median([r.classify_ms for r in rows])) if rows else 0.0
    return total


def extraction_section(rows: list[ImageSymbolMetrics]) -> list[dict[str, Any]]:
    """Rows of the extraction table (one per image, then the scene total)."""
    return [{"scene": r.scene, "frame": "all" if r.frame < 0 else r.frame, "camera": r.camera,
             "truth": r.truth, "detections": r.detections, "recall_%": 100 * r.recall,
             "spurious": r.spurious, "spurious_%": 100 * r.spurious_rate, "outside": r.outside,
             "extract_ms": r.extract_ms} for r in rows]


def classification_section(rows: list[ImageSymbolMetrics]) -> list[dict[str, Any]]:
    """Rows of the classification table."""
    return [{"scene": r.scene, "frame": "all" if r.frame < 0 else r.frame, "camera": r.camera,
             "matched": r.matched, "accuracy_%": 100 * r.accuracy,
             "confident_acc_%": 100 * r.confident_accuracy, "unknown": r.unknown,
             "classify_ms": r.classify_ms} for r in rows]


def confusion_section(total: ImageSymbolMetrics, names: list[str]) -> dict[str, Any]:
    """Confusion matrix (true x predicted + unknown) with class names."""
    return {"scene": total.scene, "classes": list(names), "columns": list(names) + ["unknown"],
            "matrix": total.confusion}


def format_table(rows: list[dict[str, Any]], title: str = "") -> str:
    """Plain text table of dict rows (floats with 2-3 decimals)."""
    if not rows:
        return f"{title}\n(no rows)\n" if title else "(no rows)\n"
    keys = list(rows[0])

    def cell(v: Any) -> str:
        if isinstance(v, float):
            return "nan" if v != v else (f"{v:.3f}" if abs(v) < 100 else f"{v:.2f}")
        return str(v)

    cells = [[cell(r.get(k, "")) for k in keys] for r in rows]
    widths = [max(len(k), *(len(c[i]) for c in cells)) for i, k in enumerate(keys)]
    lines = [title] if title else []
    lines.append("  ".join(k.rjust(w) for k, w in zip(keys, widths)))
    lines += ["  ".join(c.rjust(w) for c, w in zip(row, widths)) for row in cells]
    return "\n".join(lines) + "\n"


def format_confusion(section: dict[str, Any]) -> str:
    """Confusion matrix as a text table."""
    rows = [{"true \\ predicted": name, **{col: int(v) for col, v in zip(section["columns"], row)}}
            for name, row in zip(section["classes"], section["matrix"])]
    return format_table(rows, f"confusion matrix, {section['scene']}")


def to_json(rows: list[ImageSymbolMetrics]) -> list[dict[str, Any]]:
    """Per-image figures as JSON-able dicts (counts, rates, confusion)."""
    out = []
    for r in rows:
        d = asdict(r)
        d.update(recall=r.recall, spurious_rate=r.spurious_rate, accuracy=r.accuracy,
                 confident_accuracy=r.confident_accuracy)
        out.append(d)
    return out
