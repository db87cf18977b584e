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

A live node passes ``on_touch``: the touch stage then runs in a worker thread of its own,
frame after frame in order, while the calling thread goes on to the next frame's pipeline
(the frames overlap on two cores: the touch stage and slip, 2-3 ms a frame, no longer add
to the time each frame holds the node).  Their outputs, and those of :meth:`poll_touch`,
reach ``on_touch`` from that thread, in the frames' order.
"""
from __future__ import annotations

import queue
import threading
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from tactile_sl_common import signals
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
                 catch_up: int | None = None,
                 on_touch: Callable[[TouchFrame, Any], None] | None = None,
                 on_touch_error: Callable[[BaseException], None] | None = None) -> None:
        """The step of ``pipeline``, with touch outputs unless ``sensor`` is None.

        ``background``: a live node's reference is prepared in a worker thread (frames keep
        flowing; their outputs come late, at most ``catch_up`` per frame); offline it is
        prepared in line.  ``on_touch(touch, tag)``: run the touch stage in a worker thread
        and hand each frame's outputs there (see the module doc); an exception in it goes
        to ``on_touch_error``.
        """
        self.pipeline = pipeline
        self.touch: TouchDriver | None = None
        self._worker: _InOrderWorker | None = None
        if sensor is not None:
            pattern = pipeline.pattern
            self.touch = TouchDriver(sensor, pattern.array.shape, pattern.pitch_m,
                                     bool(pipeline.params.decode.mirrored), touch_params,
                                     background, catch_up)
            if on_touch is not None:
                self._worker = _InOrderWorker(self._run_touch, on_touch,
                                              on_touch_error or _reraise)

    @property
    def touch_ready(self) -> bool:
        """Touch outputs are on and a reference exists."""
        return self.touch is not None and self.touch.ready

    @signals.held()     # a signal waits for the frame's end (tactile_sl_common.signals)
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

    @signals.held()     # a signal waits for the frame's end (tactile_sl_common.signals)
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
        frame_id = stereo.frame_id or camera_frame
        if self._worker is not None:          # outputs come to on_touch, from the worker
            self._worker.submit((stereo.points, tag, frame_id))
            return SensorOutputs(stereo)
        return SensorOutputs(stereo, self.touch.frame(stereo.points, tag, frame_id))

    @signals.held()     # a signal waits for the frame's end (tactile_sl_common.signals)
    def poll_touch(self) -> TouchFrame | None:
        """Between frames: install a reference prepared in the background, the backlog.

        With ``on_touch`` the poll runs in the touch worker, after the frames before it, and
        its outputs go to ``on_touch`` (None is returned); else they are returned.
        """
        if self.touch is None:
            return TouchFrame()
        if self._worker is not None:
            self._worker.submit(None)
            return None
        return self.touch.poll()

    def _run_touch(self, job: tuple[np.ndarray, Any, str] | None) -> tuple[TouchFrame, Any]:
        assert self.touch is not None
        if job is None:
            return self.touch.poll(), None
        points, tag, frame_id = job
        return self.touch.frame(points, tag, frame_id), tag

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
        """Stop the pipeline's worker thread and the touch worker (after its queued frames)."""
        if self._worker is not None:
            self._worker.close()
            self._worker = None
        self.pipeline.close()


def _reraise(exc: BaseException) -> None:
    raise exc


class _InOrderWorker:
    """One thread that runs the jobs submitted to it in their order.

    The queue holds a few frames (a submitter waits when it is full: the touch stage is a
    fraction of a frame's time, so it never should); ``None`` jobs are polls.
    """

    def __init__(self, run: Callable[[Any], tuple[TouchFrame, Any]],
                 deliver: Callable[[TouchFrame, Any], None],
                 on_error: Callable[[BaseException], None], depth: int = 8) -> None:
        self._run, self._deliver, self._on_error = run, deliver, on_error
        self._jobs: queue.Queue[tuple[bool, Any]] = queue.Queue(maxsize=depth)
        self._thread = threading.Thread(target=self._loop, daemon=True, name="touch")
        self._thread.start()

    def submit(self, job: Any) -> None:
        self._jobs.put((True, job))

    def close(self, timeout: float = 5.0) -> None:
        self._jobs.put((False, None))
        self._thread.join(timeout)

    def _loop(self) -> None:
        while True:
            more, job = self._jobs.get()
            if not more:
                return
            try:
                self._deliver(*self._run(job))
            except Exception as exc:     # reported by the owner (a node logs it)
                self._on_error(exc)
