"""A rendered stereo frame of the pattern, run once before a live decoder takes images (no rclpy).

A node's camera workers warm their own code at start (``camera_processes._warm_up``), but
the node's process met its decoding, stereo and outlier code only with the first real
frame: that frame took 43-50 ms through the graph on a 2-vCPU VM (decode 9.5-16.7 ms, against
1-2 ms later), while the next one waited in a depth-1 input queue.  :func:`warm_up` runs
one synthetic pair through the whole pipeline instead: the pattern's artwork rendered flat
and fronto-parallel (:func:`~tactile_sl_decoder.pattern.artwork.render_array`), seen by an
ideal rig 17.6 mm away, then forgets it, so the first real frame is decoded as if it were
the first.
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np

from tactile_sl_common.camera_info import CameraCalibration
from tactile_sl_decoder.pattern.artwork import render_array
from tactile_sl_decoder.pattern.shapes import default_primitives
from tactile_sl_decoder.stereo.stereo import StereoRig

WIDTH, HEIGHT = 640, 480
FOCAL_PX = 600.0
PITCH_PX = 17.0
"""Glyph spacing of the rendered frame, px (the sensor's 12-30 px range)."""
BASELINE_M = 0.003
DEFAULT_PITCH_M = 5e-4


def pattern_pair(array: np.ndarray, symbols: int, pitch_m: float = 0.0,
                 mirrored: bool = False) -> tuple[np.ndarray, np.ndarray, StereoRig]:
    """(left, right) grey images of the pattern ``array`` and the ideal rig that sees them.

    The pad lies at the depth where its pitch spans :data:`PITCH_PX` (pinhole: u = f X / Z);
    the right camera sits :data:`BASELINE_M` to the left camera's +x, so every glyph moves
    by the disparity f B / Z (Hartley and Zisserman, Multiple View Geometry, 2nd ed., eq.
    9.1 for a rectified pair).  Ink at grey 60 on a pad at 200, the default glyph shapes of
    the alphabet; mirrored artwork where the cameras see it mirrored.
    """
    rows, cols = array.shape
    pattern = SimpleNamespace(rows=rows, cols=cols, array=np.asarray(array),
                              primitives=default_primitives(int(symbols)))
    art, _layout = render_array(pattern, PITCH_PX, supersample=4)  # type: ignore[arg-type]
    if mirrored:
        art = art[:, ::-1]
    gray = np.full((HEIGHT, WIDTH), 200, np.uint8)
    h, w = min(HEIGHT, art.shape[0]), min(WIDTH, art.shape[1])
    ay, ax = (art.shape[0] - h) // 2, (art.shape[1] - w) // 2
    gy, gx = (HEIGHT - h) // 2, (WIDTH - w) // 2
    gray[gy:gy + h, gx:gx + w] = (60 + art[ay:ay + h, ax:ax + w].astype(np.float32)
                                  * (140.0 / 255.0)).astype(np.uint8)
    depth = FOCAL_PX * (pitch_m or DEFAULT_PITCH_M) / PITCH_PX
    shift = int(round(FOCAL_PX * BASELINE_M / depth))
    right = np.full_like(gray, 200)
    right[:, :WIDTH - shift] = gray[:, shift:]
    k = np.array([[FOCAL_PX, 0.0, WIDTH / 2.0], [0.0, FOCAL_PX, HEIGHT / 2.0],
                  [0.0, 0.0, 1.0]])
    p_right = np.hstack([k, np.array([[-FOCAL_PX * BASELINE_M], [0.0], [0.0]])])
    rig = StereoRig(CameraCalibration(WIDTH, HEIGHT, k, np.zeros(5)),
                    CameraCalibration(WIDTH, HEIGHT, k, np.zeros(5), P=p_right))
    return gray, right, rig


def warm_up(pipeline: Any) -> int:
    """Run one rendered pair through ``pipeline`` (a StereoPipeline), then forget it.

    Returns the points it decoded (a check that the warm-up exercised the whole path).
    """
    pattern = pipeline.pattern
    left, right, rig = pattern_pair(pattern.array, pattern.symbols, pattern.pitch_m,
                                    pipeline.params.decode.mirrored)
    try:
        result = pipeline.process(left, right, rig, rig)
    finally:
        pipeline.forget_frames()
    return len(result.points)
