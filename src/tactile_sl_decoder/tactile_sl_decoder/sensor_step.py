"""One stereo frame through the whole sensor: points, then touch, slip and the tare policy.

:class:`SensorStep` is the per-frame driver of the decoder node, ``tactile-sl replay``, the
evaluation (:mod:`tactile_sl_decoder.tooling.bag_runs`) and the benchmarks: the shared
:class:`~tactile_sl_decoder.pipeline.StereoPipeline` turns the frame into points, and the
:class:`~tactile_sl_decoder.touch.driver.TouchDriver` turns those into the touch outputs
(field, wrench, contact, depth, slip), keeping the reference and its backlog.  So the ROS
graph and the offline tools give the same bytes for the same frames, and the frame's
sequence (pipeline, touch, a failed reference started again) is written once.

Bad input raises :class:`~tactile_sl_decoder.glyphs.PipelineInputError` (or
``ImageFormatError``, ``ValueError``) from the pipeline, before the touch stage sees the
frame: callers skip the frame and carry on.  No rclpy here.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from tactile_sl_decoder.glyphs import Glyphs
from tactile_sl_decoder.pipeline import StereoPipeline, StereoResult
from tactile_sl_decoder.touch.driver import TouchDriver, TouchFrame
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.stage import TouchParams


@dataclass
class SensorOutputs:
    """What one stereo frame gave: its points (and glyphs), and its touch outputs."""

    stereo: StereoResult
    touch: TouchFrame = field(default_factory=TouchFrame)   # empty when touch is off


class SensorStep:
    """The pipeline and, with a sensor file, the touch stage, frame by frame."""

    def __init__(self, pipeline: StereoPipeline, sensor: SensorConfig | None = None,
                 touch_params: TouchParams | None = None, background: bool = False,
                 catch_up: int | None = None) -> None:
        """The step of ``pipeline``, with touch outputs unless ``sensor`` is None.

        ``background``: a live node's reference is prepared in a worker thread (frames keep
        flowing; their outputs come late, at most ``catch_up`` per frame); offline it is
        prepared in line.
        """
        self.pipeline = pipeline
        self.touch: TouchDriver | None = None
        if sensor is not None:
            pattern = pipeline.pattern
            self.touch = TouchDriver(sensor, pattern.array.shape, pattern.pitch_m,
                                     bool(pipeline.params.decode.mirrored), touch_params,
                                     background, catch_up)

    @property
    def touch_ready(self) -> bool:
        """Touch outputs are on and a reference exists."""
        return self.touch is not None and self.touch.ready

    def process(self, left_gray: np.ndarray, right_gray: np.ndarray, left_info: Any,
                right_info: Any, tag: Any = None, camera_frame: str = "",
                on_points: Callable[[StereoResult], None] | None = None,
                label_hook: Callable[[Glyphs, Glyphs], None] | None = None) -> SensorOutputs:
        """One stereo pair of grey images and their CameraInfo: points, then touch.

        ``tag`` identifies the frame (a node passes its stamp): frames that wait for a
        reference come back with it.  ``camera_frame``: the frame id when the CameraInfo
        names none.  ``on_points(result)`` is called as soon as the points exist, before the
        touch stage runs (a node publishes them without waiting).  ``label_hook``: see
        :meth:`StereoPipeline.process`.
        """
        stereo = self.pipeline.process(left_gray, right_gray, left_info, right_info,
                                       label_hook=label_hook)
        return self._touch(stereo, tag, camera_frame, on_points)

    def process_symbols(self, left: Glyphs, right: Glyphs, left_info: Any, right_info: Any,
                        tag: Any = None, camera_frame: str = "",
                        on_points: Callable[[StereoResult], None] | None = None
                        ) -> SensorOutputs:
        """The stage nodes' labelled SymbolArrays (as :class:`Glyphs`): points, then touch."""
        stereo = self.pipeline.process_symbols(left, right, left_info, right_info)
        return self._touch(stereo, tag, camera_frame, on_points)

    def _touch(self, stereo: StereoResult, tag: Any, camera_frame: str,
               on_points: Callable[[StereoResult], None] | None) -> SensorOutputs:
        if on_points is not None:
            on_points(stereo)
        if self.touch is None:
            return SensorOutputs(stereo)
        return SensorOutputs(stereo, self.touch.frame(stereo.points, tag,
                                                      stereo.frame_id or camera_frame))

    def set_mirrored(self, mirrored: bool) -> None:
        """The cameras see the artwork mirrored (or not).

        Decoding changes, and the touch reference is taken again from the next frames.
        """
        self.pipeline.params.decode.mirrored = bool(mirrored)
        if self.touch is not None:
            self.touch.restart(bool(mirrored))

    def forget_frames(self) -> None:
        """A new stream of frames (another bag): nothing carried from the last frames."""
        self.pipeline.forget_frames()

    def close(self) -> None:
        """Stop the pipeline's worker thread."""
        self.pipeline.close()
