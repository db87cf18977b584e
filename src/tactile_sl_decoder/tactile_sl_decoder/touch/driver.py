"""The touch stage frame by frame: the one place that builds it and applies the tare policy.

:class:`TouchDriver` owns a :class:`~tactile_sl_decoder.touch.stage.TouchStage` and hands each
frame's points to it.  What every caller did around :meth:`TouchStage.update` is here, once:

* **Tare policy**: a reference that turns out unusable (:class:`ReferenceError`, e.g. the
  pad's fit failed) is dropped and a new one started from the next frames; the frame says so
  (:attr:`TouchFrame.reference_failed`) and the caller reports it in its own way.
* **The reference**: the frame that completes the reference frames is remembered (its tag
  and camera frame), and :attr:`TouchFrame.reference_ready` announces the reference when it
  is installed, inline at that frame or later from the background preparation.
* **The backlog**: frames that waited for a reference prepared in the background come back
  with their outputs, oldest first, at most ``catch_up`` per call
  (:meth:`TouchStage.drain`).

:class:`~tactile_sl_decoder.sensor_step.SensorStep` runs it after the pipeline for the
decoder node, ``tactile-sl replay``, the evaluation and the benchmarks; the force
calibration runs it over frames decoded once.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tactile_sl_decoder.touch.reference import ReferenceError
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.stage import Reference, TouchParams, TouchResult, TouchStage


@dataclass
class ReferenceReady:
    """A new reference is installed: it, and the frame whose points completed it."""

    reference: Reference
    tag: Any = None        # that frame's tag (its stamp in the node): pad_pose is stamped so
    frame_id: str = ""     # that frame's camera frame: the pad pose is expressed in it


@dataclass
class TouchFrame:
    """What one call gave: this frame's outputs and what happened to the reference."""

    result: TouchResult | None = None
    """This frame's outputs (None while the reference is built or prepared, or no points)."""
    caught_up: list[tuple[Any, TouchResult]] = field(default_factory=list)
    """(tag, outputs) of frames that waited for the reference, oldest first."""
    reference_ready: ReferenceReady | None = None
    """Set on the call that installed a new reference."""
    reference_failed: ReferenceError | None = None
    """Set when the reference was unusable: a new one is taken from the next frames."""


class TouchDriver:
    """Runs the touch stage over a stream of frames with the tare policy (see module doc)."""

    def __init__(self, sensor: SensorConfig, shape: tuple[int, int], pitch: float,
                 mirrored: bool = False, params: TouchParams | None = None,
                 background: bool = False, catch_up: int | None = None) -> None:
        self.stage = TouchStage(sensor, shape, pitch, mirrored, params, background)
        self.catch_up = catch_up        # backlog frames handed out per call; None: all
        self._completing: tuple[Any, str] = (None, "")   # tag, camera frame
        # frames may come from a worker thread (SensorStep's touch worker) while a node's
        # executor tares, restarts or polls: one call at a time
        self._lock = threading.RLock()

    def restart(self, mirrored: bool) -> None:
        """A new stage, same sensor and settings: a new reference from the next frames."""
        with self._lock:
            old = self.stage
            self.stage = TouchStage(old.sensor, old.shape, old.pitch, mirrored, old.params,
                                    old.background)
            self.stage.slip_wanted = old.slip_wanted

    def tare(self) -> tuple[bool, str]:
        """Start a new reference from the next frames (refused while the pad is pressed)."""
        with self._lock:
            return self.stage.tare()

    @property
    def ready(self) -> bool:
        """A reference exists and frames produce touch outputs."""
        return self.stage.ready

    def frame(self, points: np.ndarray, tag: Any = None, frame_id: str = "") -> TouchFrame:
        """Touch outputs of one frame's contract points, and the reference's news.

        ``tag`` comes back with the frame's outputs if it has to wait for a reference
        prepared in the background; ``frame_id`` is its camera frame (for the pad pose).
        """
        with self._lock:
            return self._frame(points, tag, frame_id)

    def _frame(self, points: np.ndarray, tag: Any, frame_id: str) -> TouchFrame:
        stage = self.stage
        had_reference, was_preparing = stage.ready, stage.preparing
        try:
            result = stage.update(points, tag=tag)
        except ReferenceError as exc:
            stage.tare()
            return TouchFrame(reference_failed=exc)
        out = TouchFrame(result)
        if not had_reference and not was_preparing and (stage.preparing or stage.ready):
            self._completing = (tag, frame_id)        # this frame completed the reference
        if stage.ready and not had_reference:
            out.reference_ready = self._ready()
        out.caught_up = stage.drain(self.catch_up)
        return out

    def poll(self) -> TouchFrame:
        """Between frames (a node's timer): install a reference prepared in the background.

        Returns the backlog's next outputs and the reference's news, as :meth:`frame` does.
        """
        with self._lock:
            return self._poll()

    def _poll(self) -> TouchFrame:
        out = TouchFrame()
        stage = self.stage
        if stage.preparing:
            try:
                if stage.poll():
                    out.reference_ready = self._ready()
            except ReferenceError as exc:
                stage.tare()
                out.reference_failed = exc
        out.caught_up = stage.drain(self.catch_up)
        return out

    def _ready(self) -> ReferenceReady:
        assert self.stage.reference is not None
        return ReferenceReady(self.stage.reference, *self._completing)
