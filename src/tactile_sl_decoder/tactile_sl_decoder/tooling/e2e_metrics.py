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
"""
from __future__ import annotations

import sys
from dataclasses import asdict, dataclass, field
from typing import Any, Iterable, TextIO

import numpy as np
from scipy.spatial import cKDTree

from tactile_sl_common.clouds import cloud_to_arrays


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
