"""Bag drivers: the sensor over a bag, as ``tactile-sl replay`` runs it (no rclpy).

``evaluate_bag`` runs the shared :class:`~tactile_sl_decoder.sensor_step.SensorStep` (points
only) over a bag (the same path as ``tactile-sl replay``) and returns per-frame and per-bag
figures.  ``evaluate_touch_bag`` runs it with the touch stage and returns the touch figures
of every frame (definitions in :mod:`~tactile_sl_decoder.tooling.e2e_metrics` and
:mod:`~tactile_sl_decoder.tooling.touch_metrics`).  ``displacement_errors`` gives each
frame's measured displacement error per cell, as the points give it (the touch bound's
noise, :mod:`~tactile_sl_decoder.tooling.touch_bound`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, TextIO

import numpy as np

from tactile_sl_common.images import to_gray
from tactile_sl_decoder.frames import bag_frames, count_bag_frames
from tactile_sl_decoder.glyphs import PipelineInputError
from tactile_sl_decoder.sensor_step import SensorOutputs, SensorStep
from tactile_sl_decoder.tooling.e2e_metrics import (
    BagMetrics,
    FrameMetrics,
    aggregate,
    frame_metrics,
)
from tactile_sl_decoder.tooling.evaluation import FRAME_INPUT_ERRORS, SkipCallback
from tactile_sl_decoder.tooling.progress import progress_bar
from tactile_sl_decoder.tooling.touch_metrics import (
    NAN,
    TouchFrameMetrics,
    compare_frame,
    matched_cells,
    read_truths,
)
from tactile_sl_decoder.touch.stage import TouchParams
from tactile_sl_decoder.touch.weights import WeightParams


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
                 progress: TextIO | None = None, max_frames: int = 0,
                 on_skip: SkipCallback | None = None
                 ) -> tuple[list[FrameMetrics], BagMetrics]:
    """Run the pipeline over a bag with ground truth; per-frame and per-bag figures.

    ``match_tol_m`` defaults to half the pattern pitch (or 0.25 mm if the pitch is unknown).
    Frames without ground truth are skipped; so are frames whose input is unusable
    (:data:`~tactile_sl_decoder.tooling.evaluation.FRAME_INPUT_ERRORS`), each passed to
    ``on_skip(stamp_ns, why)`` (without it, the error is raised).
    """
    pitch = float(getattr(pipeline.pattern, "pitch_m", 0.0) or 0.0)
    tol = match_tol_m if match_tol_m is not None else (0.5 * pitch if pitch > 0 else 2.5e-4)
    total = count_bag_frames(path, namespace)
    frames: list[FrameMetrics] = []
    step = SensorStep(pipeline)    # points only
    step.forget_frames()           # a bag is a stream of its own: nothing from the last one
    for i, frame in enumerate(bag_frames(path, namespace)):
        if max_frames and i >= max_frames:
            break
        if progress is not None:
            progress_bar(progress, i + 1, total, Path(path).name)
        if frame.ground_truth is None:
            continue
        out = _process(step, frame, on_skip, label_hook=label_hook)
        if out is None:
            continue
        result = out.stereo
        fm = frame_metrics(result.points, frame.ground_truth, tol, frame.stamp_ns)
        fm.timings_ms = dict(result.timings_ms)
        frames.append(fm)
    if progress is not None:
        progress.write("\n")
    return frames, aggregate(Path(path).stem, frames)


def evaluate_touch_bag(path: str | Path, pipeline: Any, sensor: Any, reference_frames: int = 1,
                       namespace: str = "/tactile", progress: TextIO | None = None,
                       max_frames: int = 0, untouched: bool = False,
                       on_skip: SkipCallback | None = None,
                       touch_params: TouchParams | None = None) -> list[TouchFrameMetrics]:
    """Pipeline + touch stage over a bag (as ``tactile-sl replay``), each frame decoded once.

    Frames used for the reference give no figures.  ``untouched``: the bag has no touch
    ground truth and the pad is at rest throughout (a control: zero truth).
    Timings per frame: ``pipeline`` (the pipeline's total), ``touch`` (the stage's) and
    ``slip`` (the slip estimate's part of it).  A frame with unusable input goes to
    ``on_skip`` as in :func:`evaluate_bag`.  ``touch_params``: the touch stage's settings
    (default: all defaults with ``reference_frames``).
    """
    truths = {} if untouched else read_truths(path, namespace)
    if touch_params is None:
        touch_params = TouchParams(reference_frames=reference_frames)
    name = Path(path).stem
    out: list[TouchFrameMetrics] = []
    for frame, truth, outputs in _touched_frames(path, pipeline, sensor, touch_params,
                                                 namespace, truths, untouched, on_skip,
                                                 progress, max_frames):
        result, touch = outputs.stereo, outputs.touch.result
        m = compare_frame(touch, truth, name, frame.stamp_ns)
        m.timings_ms = {"pipeline": float(result.timings_ms.get("total", NAN))}
        if touch is not None:
            m.timings_ms["touch"] = float(touch.timings_ms.get("touch", NAN))
            m.timings_ms["slip"] = float(touch.timings_ms.get("slip", NAN))
        out.append(m)
    return out


def _touched_frames(path: str | Path, pipeline: Any, sensor: Any, touch_params: TouchParams,
                    namespace: str, truths: dict[int, Any], untouched: bool = False,
                    on_skip: SkipCallback | None = None, progress: TextIO | None = None,
                    max_frames: int = 0) -> Iterator[tuple[Any, Any, SensorOutputs]]:
    """(frame, its truth, its outputs) of every frame of a bag after the touch reference.

    Frames without a truth are passed over unless ``untouched`` (truth None then); a frame
    with unusable input goes to ``on_skip`` (raised without one).
    """
    step = SensorStep(pipeline, sensor, touch_params)
    name = Path(path).stem
    total = count_bag_frames(path, namespace) if progress is not None else 0
    step.forget_frames()           # a bag is a stream of its own: nothing from the last one
    for i, frame in enumerate(bag_frames(path, namespace, ground_truth=False)):
        if max_frames and i >= max_frames:
            break
        if progress is not None:
            progress_bar(progress, i + 1, total, name)
        truth = truths.get(frame.stamp_ns)
        if truth is None and not untouched:
            continue
        was_ready = step.touch_ready
        outputs = _process(step, frame, on_skip)
        if outputs is None or not was_ready:
            continue                       # bad input, or a reference frame
        yield frame, truth, outputs
    if progress is not None:
        progress.write("\n")


@dataclass(frozen=True)
class DisplacementErrors:
    """One frame's measured displacement minus the truth, per cell decoded in both (pad frame)."""

    cells: np.ndarray      # (N,) their keys (touch_metrics.cell_keys), ascending
    errors: np.ndarray     # (N, 3) m
    rest_xy: np.ndarray    # (N, 2) m, the cells' true rest positions


def displacement_errors(path: str | Path, pipeline: Any, sensor: Any,
                        namespace: str = "/tactile") -> dict[int, DisplacementErrors]:
    """Per touched frame (by stamp, ns) of a touch scene's bag, its displacement errors.

    The displacement is as the points give it (reference = the first frame, the per-cell
    weights off: no cleaning, no fitted field), so that its errors are the points' own.
    """
    truths = read_truths(path, namespace)
    out: dict[int, DisplacementErrors] = {}
    for frame, truth, outputs in _touched_frames(
            path, pipeline, sensor, TouchParams(weights=WeightParams(enabled=False)),
            namespace, truths):
        result = outputs.touch.result
        if result is None:
            continue
        cells, i, j = matched_cells(result.rows, result.cols, truth.rows, truth.cols)
        rest = np.asarray(truth.position, np.float64) - np.asarray(truth.displacement)
        out[frame.stamp_ns] = DisplacementErrors(
            cells, np.asarray(result.displacement, np.float64)[i] - truth.displacement[j],
            rest[j, :2])
    return out


def _process(step: SensorStep, frame: Any, on_skip: SkipCallback | None,
             label_hook: Callable | None = None) -> SensorOutputs | None:
    """The step's outputs for a bag frame, or None (after ``on_skip``) if its input is bad."""
    try:
        if frame.left_info is None or frame.right_info is None:
            raise PipelineInputError("no camera_info for this frame")
        return step.process(to_gray(frame.left_image), to_gray(frame.right_image),
                            frame.left_info, frame.right_info, label_hook=label_hook)
    except FRAME_INPUT_ERRORS as exc:
        if on_skip is None:
            raise
        on_skip(frame.stamp_ns, str(exc))
        return None
