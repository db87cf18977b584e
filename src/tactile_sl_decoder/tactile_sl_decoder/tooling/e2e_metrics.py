"""End-to-end figures of the decoder against ground truth (no rclpy).

For one stereo frame, the decoder's cloud is compared with the bag's
``/tactile/ground_truth/points`` (true 3-D cell centres of every glyph visible in both
images, physical left optical frame):

* **correct**: an output point whose cell is in the ground truth and lies within
  ``match_tol`` (default half a pattern pitch) of that cell's true centre;
* **wrong**: an output point that is not where its cell is: its cell is in the ground truth
  but far from it, or not in the ground truth while a *different* ground-truth cell lies
  within ``match_tol`` of it (a real glyph decoded to another cell);
* **extra**: output cells absent from the ground truth and near no ground-truth point
  (e.g. a glyph the truth counts as hidden); reported, not counted as wrong;
* **coverage** = correct / visible, **wrong-cell rate** = wrong / output points,
* 3-D error of correct points: RMSE, median, 95th percentile (metres).

``evaluate_bag`` runs the shared :class:`~tactile_sl_decoder.pipeline.StereoPipeline` over
a bag (the same path as ``tactile-sl replay``) and returns per-frame and per-bag figures.
"""
from __future__ import annotations

import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, TextIO

import numpy as np
from scipy.spatial import cKDTree

from tactile_sl_camera.clouds import cloud_to_arrays


class _Rates:
    """Coverage and wrong-cell rate from the counts (frame or pooled over a bag)."""

    visible: int
    points: int
    correct: int
    wrong: int

    @property
    def coverage(self) -> float:
        """Share of ground-truth-visible glyphs decoded to the right cell and triangulated."""
        return self.correct / self.visible if self.visible else float("nan")

    @property
    def wrong_rate(self) -> float:
        """Share of output points at a wrong cell."""
        return self.wrong / self.points if self.points else 0.0


@dataclass
class FrameMetrics(_Rates):
    """Figures of one stereo frame."""

    stamp_ns: int
    visible: int
    points: int
    correct: int
    wrong: int
    extra: int
    errors_m: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    timings_ms: dict[str, float] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """Plain dict (JSON-friendly) of the frame's figures."""
        return {"stamp_ns": self.stamp_ns, "visible": self.visible, "points": self.points,
                "correct": self.correct, "wrong": self.wrong, "extra": self.extra,
                "coverage": self.coverage, "wrong_rate": self.wrong_rate,
                **_error_stats(self.errors_m)}


@dataclass
class BagMetrics(_Rates):
    """Figures pooled over the frames of one bag."""

    name: str
    frames: int
    frames_with_points: int
    visible: int
    points: int
    correct: int
    wrong: int
    extra: int
    rmse_m: float
    median_m: float
    p95_m: float
    max_m: float
    coverage_min: float
    timings_ms: dict[str, float] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """Plain dict (JSON-friendly) of the bag's figures."""
        out = asdict(self)
        out.update(coverage=self.coverage, wrong_rate=self.wrong_rate)
        return out


def _error_stats(errors: np.ndarray) -> dict[str, float]:
    if len(errors) == 0:
        return {"rmse_m": float("nan"), "median_m": float("nan"), "p95_m": float("nan"),
                "max_m": float("nan")}
    return {"rmse_m": float(np.sqrt(np.mean(errors ** 2))),
            "median_m": float(np.median(errors)),
            "p95_m": float(np.percentile(errors, 95)), "max_m": float(errors.max())}


def frame_metrics(points: np.ndarray | Any, ground_truth: np.ndarray | Any, match_tol_m: float,
                  stamp_ns: int = 0) -> FrameMetrics:
    """Compare one output cloud with its ground truth (structured arrays or PointCloud2)."""
    pts = points if isinstance(points, np.ndarray) else cloud_to_arrays(points)
    gt = ground_truth if isinstance(ground_truth, np.ndarray) else cloud_to_arrays(ground_truth)
    xyz = np.column_stack([pts["x"], pts["y"], pts["z"]]).astype(np.float64)
    gxyz = np.column_stack([gt["x"], gt["y"], gt["z"]]).astype(np.float64)
    key = pts["row"].astype(np.int64) * 1_000_003 + pts["col"]
    gkey = gt["row"].astype(np.int64) * 1_000_003 + gt["col"]
    order = np.argsort(gkey)
    gkey_sorted = gkey[order]
    pos = np.searchsorted(gkey_sorted, key)
    pos = np.minimum(pos, max(len(gkey_sorted) - 1, 0))
    in_gt = (len(gkey_sorted) > 0) & (gkey_sorted[pos] == key) if len(key) else np.zeros(0, bool)
    gi = order[pos] if len(gkey_sorted) else np.zeros(len(key), int)
    err = np.full(len(key), np.inf)
    if len(key) and len(gkey_sorted):
        err[in_gt] = np.linalg.norm(xyz[in_gt] - gxyz[gi[in_gt]], axis=1)
    correct = in_gt & (err <= match_tol_m)
    wrong = in_gt & ~correct
    extra = ~in_gt
    if extra.any() and len(gxyz):
        d, j = cKDTree(gxyz).query(xyz[extra])
        near_other = d <= match_tol_m          # a real glyph with another (true) cell
        idx = np.flatnonzero(extra)
        wrong[idx[near_other]] = True
        extra[idx[near_other]] = False
    return FrameMetrics(stamp_ns, len(gt), len(pts), int(correct.sum()), int(wrong.sum()),
                        int(extra.sum()), err[correct])


def aggregate(name: str, frames: Iterable[FrameMetrics]) -> BagMetrics:
    """Pool per-frame figures into per-bag figures."""
    frames = list(frames)
    errors = np.concatenate([f.errors_m for f in frames]) if frames else np.zeros(0)
    stats = _error_stats(errors)
    cov = [f.coverage for f in frames if f.visible]
    timings: dict[str, float] = {}
    keys = {k for f in frames for k in f.timings_ms}
    for k in sorted(keys):
        vals = [f.timings_ms[k] for f in frames if k in f.timings_ms]
        timings[k] = float(np.median(vals))
    return BagMetrics(name, len(frames), sum(1 for f in frames if f.points),
                      sum(f.visible for f in frames), sum(f.points for f in frames),
                      sum(f.correct for f in frames), sum(f.wrong for f in frames),
                      sum(f.extra for f in frames), stats["rmse_m"], stats["median_m"],
                      stats["p95_m"], stats["max_m"], float(min(cov)) if cov else float("nan"),
                      timings)


def flip_labels_hook(rate: float, symbols: int, seed: int = 0) -> Callable[[Any, Any], None]:
    """Label hook for :meth:`StereoPipeline.process` that flips labels at random.

    Each known (classified) label is replaced by another symbol with probability ``rate``
    (robustness benchmark: errors injected after classification).
    """
    rng = np.random.default_rng(seed)

    def hook(left: Any, right: Any) -> None:
        for g in (left, right):
            known = g.label < symbols
            flip = known & (rng.random(len(g.label)) < rate)
            g.label = g.label.copy()
            g.label[flip] = (g.label[flip].astype(np.int64)
                             + rng.integers(1, symbols, int(flip.sum()))) % symbols
    return hook


def evaluate_bag(path: str | Path, pipeline: Any, namespace: str = "/tactile",
                 match_tol_m: float | None = None, label_hook: Callable | None = None,
                 progress: TextIO | None = None, max_frames: int = 0
                 ) -> tuple[list[FrameMetrics], BagMetrics]:
    """Run the pipeline over a bag with ground truth; per-frame and per-bag figures.

    ``match_tol_m`` defaults to half the pattern pitch (or 0.25 mm if the pitch is unknown).
    Frames without ground truth are skipped.
    """
    from tactile_sl_camera.images import to_gray
    from tactile_sl_decoder.frames import bag_frames, count_bag_frames

    pitch = float(getattr(pipeline.pattern, "pitch_m", 0.0) or 0.0)
    tol = match_tol_m if match_tol_m is not None else (0.5 * pitch if pitch > 0 else 2.5e-4)
    total = count_bag_frames(path, namespace)
    frames: list[FrameMetrics] = []
    for i, frame in enumerate(bag_frames(path, namespace)):
        if max_frames and i >= max_frames:
            break
        if progress is not None:
            progress_bar(progress, i + 1, total, Path(path).name)
        if frame.ground_truth is None:
            continue
        result = pipeline.process(to_gray(frame.left_image), to_gray(frame.right_image),
                                  frame.left_info, frame.right_info, label_hook=label_hook)
        fm = frame_metrics(result.points, frame.ground_truth, tol, frame.stamp_ns)
        fm.timings_ms = dict(result.timings_ms)
        frames.append(fm)
    if progress is not None:
        progress.write("\n")
    return frames, aggregate(Path(path).stem, frames)


def progress_bar(stream: TextIO, done: int, total: int, label: str = "") -> None:
    """One-line progress bar on a terminal stream (carriage return, no newline)."""
    width = 30
    if total > 0:
        fill = int(width * min(done, total) / total)
        text = f"\r{label} [{'#' * fill}{'.' * (width - fill)}] {done}/{total}"
    else:
        text = f"\r{label} {done} frames"
    stream.write(text)
    stream.flush()


def format_table(bags: Iterable[BagMetrics], file: TextIO = sys.stdout) -> None:
    """Print the per-bag figures as a table (mm for 3-D errors)."""
    header = (f"{'bag':<24} {'frames':>6} {'visible':>8} {'coverage':>9} {'wrong':>6} "
              f"{'wrong%':>7} {'rmse mm':>8} {'med mm':>7} {'p95 mm':>7} {'min cov':>8}")
    print(header, file=file)
    for b in bags:
        print(f"{b.name:<24} {b.frames:>6} {b.visible:>8} {100 * b.coverage:>8.2f}% "
              f"{b.wrong:>6} {100 * b.wrong_rate:>6.3f}% {1e3 * b.rmse_m:>8.4f} "
              f"{1e3 * b.median_m:>7.4f} {1e3 * b.p95_m:>7.4f} {100 * b.coverage_min:>7.1f}%",
              file=file)


def e2e_section(args: Any, bags: list[Path]) -> str:
    """`tactile-sl evaluate` report section: end-to-end figures per frame and per bag.

    Signature of ``evaluate_cmd.SECTIONS`` entries; reads ``args.pattern``,
    ``args.weights``, ``args.namespace``, ``args.max_frames``, ``args.totals_only`` and
    ``args.json`` (figures also written to ``<json stem>.e2e.json``) when present.
    """
    import io
    import json

    from tactile_sl_decoder.pipeline import PatternSpec, StereoPipeline

    classifier = None
    weights = getattr(args, "weights", None)
    if weights:
        from tactile_sl_decoder.classify.classifier import Classifier

        classifier = Classifier.load(weights)
    pattern = getattr(args, "pattern", None)
    pipe = StereoPipeline(PatternSpec.load(pattern), classifier)
    namespace = getattr(args, "namespace", "/tactile")
    per_bag: list[BagMetrics] = []
    per_frame: list[tuple[str, FrameMetrics]] = []
    try:
        for bag in bags:
            frames, summary = evaluate_bag(bag, pipe, namespace, progress=sys.stderr,
                                           max_frames=int(getattr(args, "max_frames", 0) or 0))
            per_bag.append(summary)
            per_frame += [(summary.name, f) for f in frames]
    finally:
        pipe.close()
    out = io.StringIO()
    print("End to end (decoded cells and 3-D points vs ground truth; coverage = visible "
          "glyphs decoded to the right cell and triangulated)", file=out)
    if not getattr(args, "totals_only", False):
        print(f"{'bag':<24} {'stamp':>20} {'visible':>8} {'points':>7} {'coverage':>9} "
              f"{'wrong':>6} {'rmse mm':>8} {'med mm':>7} {'p95 mm':>7} {'ms':>6}", file=out)
        for name, f in per_frame:
            s = f.summary()
            print(f"{name:<24} {f.stamp_ns:>20} {f.visible:>8} {f.points:>7} "
                  f"{100 * f.coverage:>8.2f}% {f.wrong:>6} {1e3 * s['rmse_m']:>8.4f} "
                  f"{1e3 * s['median_m']:>7.4f} {1e3 * s['p95_m']:>7.4f} "
                  f"{f.timings_ms.get('total', float('nan')):>6.1f}", file=out)
        print(file=out)
    format_table(per_bag, file=out)
    json_path = getattr(args, "json", None)
    if json_path:
        target = Path(json_path).with_suffix(".e2e.json")
        target.write_text(json.dumps({
            "bags": [b.summary() for b in per_bag],
            "frames": [dict(bag=name, **f.summary()) for name, f in per_frame]}, indent=1))
        print(f"(end-to-end figures also in {target})", file=out)
    return out.getvalue().rstrip("\n")


# ---------------------------------------------------------------------- demo pictures

CLASS_COLOURS_BGR = {0: (60, 60, 230), 1: (60, 200, 60), 2: (230, 140, 40)}
UNKNOWN_COLOUR_BGR = (160, 160, 160)


def render_overlay(gray: np.ndarray, glyphs: Any, label_every: int = 4) -> np.ndarray:
    """BGR picture of one image with its glyphs coloured by class and cells annotated.

    ``glyphs`` has ``u, v, label, row, col`` arrays (a pipeline ``Glyphs``, or
    ``symbol_array.from_message`` of a ``symbols_decoded`` message). Decoded glyphs get a
    filled dot, undecoded ones a ring; every cell whose row and column are multiples of
    ``label_every`` is written as ``row,col``.
    """
    import cv2

    img = cv2.cvtColor(np.ascontiguousarray(gray, np.uint8), cv2.COLOR_GRAY2BGR)
    u = np.asarray(glyphs.u, np.float64)
    v = np.asarray(glyphs.v, np.float64)
    label = np.asarray(glyphs.label)
    row = np.asarray(glyphs.row)
    col = np.asarray(glyphs.col)
    for i in range(len(u)):      # drawing only (no per-glyph work in the pipeline)
        colour = CLASS_COLOURS_BGR.get(int(label[i]), UNKNOWN_COLOUR_BGR)
        centre = (int(round(u[i])), int(round(v[i])))
        cv2.circle(img, centre, 3, colour, -1 if row[i] >= 0 else 1, cv2.LINE_AA)
        if row[i] >= 0 and row[i] % label_every == 0 and col[i] % label_every == 0:
            cv2.putText(img, f"{row[i]},{col[i]}", (centre[0] + 4, centre[1] - 4),
                        cv2.FONT_HERSHEY_PLAIN, 0.8, (0, 255, 255), 1, cv2.LINE_AA)
    return img


def render_cloud(points: np.ndarray | Any, size: tuple[int, int] = (640, 480)) -> np.ndarray:
    """BGR picture of a cloud seen from the cameras; colour = height above the pad's plane.

    The pad is tilted with respect to the (converging) cameras, so the colour is the signed
    distance to the cloud's least-squares plane: red is pressed towards the cameras, blue
    away; the range is written in the corner, in millimetres.
    """
    import cv2

    pts = points if isinstance(points, np.ndarray) else cloud_to_arrays(points)
    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    if len(pts) < 3:
        cv2.putText(img, f"{len(pts)} points", (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.8,
                    (0, 0, 0), 2)
        return img
    xyz = np.column_stack([pts["x"], pts["y"], pts["z"]]).astype(np.float64)
    centre = xyz.mean(axis=0)
    normal = np.linalg.svd(xyz - centre, full_matrices=False)[2][2]
    normal = normal if normal[2] < 0 else -normal          # towards the cameras
    height = (xyz - centre) @ normal
    x, y = xyz[:, 0], xyz[:, 1]
    margin = 20
    span = max(np.ptp(x), np.ptp(y), 1e-9)
    scale = (min(w, h - 30) - 2 * margin) / span
    px = (margin + (x - x.min()) * scale).astype(int)
    py = (margin + (y - y.min()) * scale).astype(int)
    lim = max(float(np.abs(height).max()), 1e-9)
    t = np.clip(0.5 + 0.5 * height / lim, 0, 1)
    colours = cv2.applyColorMap((255 * t).astype(np.uint8).reshape(-1, 1), cv2.COLORMAP_JET)
    for i in range(len(px)):     # drawing only
        cv2.circle(img, (int(px[i]), int(py[i])), 4, tuple(int(c) for c in colours[i, 0]), -1)
    cv2.putText(img, f"{len(pts)} points; height vs plane {-1e3 * lim:+.3f}..{1e3 * lim:+.3f}"
                f" mm (red = towards cameras)", (10, h - 10), cv2.FONT_HERSHEY_PLAIN, 1.0,
                (0, 0, 0), 1, cv2.LINE_AA)
    return img
