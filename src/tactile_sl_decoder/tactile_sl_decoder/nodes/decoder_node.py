"""``decoder``: stereo images (or the stage nodes' SymbolArrays) in, contract point clouds out.

Subscribes (relative names, sensor-data QoS)::

    input=images  : left/image_raw, right/image_raw          (sensor_msgs/Image)
    input=symbols : left/symbols, right/symbols              (tactile_sl_msgs/SymbolArray)
    always        : left/camera_info, right/camera_info      (sensor_msgs/CameraInfo)

Publishes ``points`` (sensor_msgs/PointCloud2, one per stereo frame, stamped exactly like
the left image), the touch outputs ``field``, ``wrench``, ``contact``, ``depth``, ``slip``
(with ``slip_markers`` for RViz) and ``pad_pose`` (see :mod:`.touch_outputs`; service
``tare``) and, for inspection, ``left/symbols_decoded`` / ``right/symbols_decoded``
(labelled and decoded SymbolArrays).
All the work is done by the shared :class:`~tactile_sl_decoder.sensor_step.SensorStep`
(pipeline, touch stage, tare policy), so ``tactile-sl replay`` on a bag gives the same points
and touch outputs.  Bad input (encodings, sizes, CameraInfo, unsynchronised stereo, empty
images) is reported with a throttled warning and the frame is skipped; the node keeps
running.  Parameters: see ``config/decoder.yaml`` and ``docs/decoder.md``.
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from tactile_sl_common.clouds import cloud_fields
from tactile_sl_common.images import ImageFormatError, to_gray
from tactile_sl_common.nodes.messages import cloud_msg
from tactile_sl_common.nodes.parameters import (
    FRAME_PREFIX_DOC,
    LiveParameters,
    dataclass_fields,
    declare_qos,
    field_docs,
    frame_prefix_check,
)
from tactile_sl_common.nodes.runner import run_node
from tactile_sl_decoder.checks import check_classifier, check_threshold, load_pattern_spec
from tactile_sl_decoder.frames import StereoSync, stamp_ns
from tactile_sl_decoder.glyphs import Glyphs, PipelineInputError
from tactile_sl_decoder.nodes.diagnostics import DecoderDiagnostics, DiagnosticLimits, Status
from tactile_sl_decoder.nodes.diagnostics_publisher import DiagnosticsPublisher
from tactile_sl_decoder.nodes.extraction_parameters import declare_extraction
from tactile_sl_decoder.nodes.touch_outputs import CATCH_UP_BURST, TouchOutputs, declare_touch
from tactile_sl_decoder.pipeline import PipelineParams, StereoPipeline, StereoResult
from tactile_sl_decoder.sensor_step import SensorStep
from tactile_sl_decoder.symbol_array import fill_message, from_message

try:
    from tactile_sl_msgs.msg import SymbolArray
except ImportError:  # pragma: no cover - interfaces not built
    SymbolArray = None


class DecoderNode(Node):
    """Runs the stereo pipeline on every synchronised stereo frame."""

    def __init__(self) -> None:
        super().__init__("decoder")
        self.params = LiveParameters(self)
        decl = self.params.declare
        ro: dict[str, Any] = {"read_only": True}
        self.input_mode = str(decl("input", "images",
            "'images': run extraction + classification in-process on left/right image_raw "
            "(lowest latency); 'symbols': consume left/right symbols from the stage nodes.",
            check=lambda v: None if v in ("images", "symbols") else
            "must be 'images' or 'symbols'", **ro))
        pattern_file = str(decl("pattern_file", "",
            "Pattern YAML (contract format); empty = the pattern the package ships.", **ro))
        allow_invalid = bool(decl("allow_invalid_pattern", False,
            "Use a pattern file that breaks its own min_hamming / window uniqueness "
            "(experiments only: cells may be wrong).", **ro))
        weights = str(decl("classifier_weights", "",
            "Classifier weights from `tactile-sl train`; empty = the shipped ones. Their "
            "class count must equal the pattern's symbols.", **ro))
        self.frame_prefix = str(decl("frame_prefix", "", FRAME_PREFIX_DOC +
            " Here: the pad frame of the touch outputs (the cloud keeps the left CameraInfo's "
            "frame, which the camera driver prefixes) and the diagnostics' hardware_id.",
            check=frame_prefix_check, **ro))
        params = PipelineParams()
        self.pipeline_params = params
        params.decode.mirrored = bool(decl("mirrored", False,
            "The cameras see the artwork mirrored (looking through the elastomer). A change "
            "takes a new touch reference.", apply=self._set_mirrored))
        sync_slop = float(decl("sync_slop", 0.0,
            "Seconds by which left/right stamps may differ when no exactly equal stamp "
            "exists (0 = exact stamps only, the contract's stereo convention).", (0.0, 10.0),
            apply=lambda v: setattr(self.sync, "slop_ns", int(v * 1e9))))
        input_depth = int(decl("input_depth", 1,
            "QoS history depth of the input subscriptions (sensor data, best effort). Small "
            "keeps latency low when the node falls behind: older frames are replaced by newer "
            "ones in the middleware instead of queueing up (1: only the newest frame waits).",
            (1, 1000), **ro))
        queue_size = int(decl("queue_size", 5,
            "Unpaired messages kept per side while waiting for the stereo partner.", (1, 1000),
            apply=lambda v: setattr(self.sync, "queue_size", int(v))))
        self._max_wait_s = float(decl("max_age", 0.5,
            "Seconds after which an unpaired message is dropped as stale.", (0.001, 3600.0),
            apply=self._set_max_age))
        self.publish_symbols = bool(decl("publish_symbols", True,
            "Publish left/right symbols_decoded (labelled + decoded SymbolArrays).", **ro))
        self.publish_patches = bool(decl("publish_patches", False,
            "Include the glyph patches in symbols_decoded (larger messages).",
            apply=lambda v: setattr(self, "publish_patches", bool(v))))
        self.publish_empty = bool(decl("publish_empty", True,
            "Publish a cloud with no point for frames that decoded nothing.",
            apply=lambda v: setattr(self, "publish_empty", bool(v))))
        params.threads = int(decl("threads", 2,
            "Worker threads for the two images of a frame: 2 extracts and classifies them "
            "concurrently, 1 = sequential.", (1, 2), **ro))
        params.cpu_threads = int(decl("cpu_threads", 1,
            "Intra-op threads of OpenCV and BLAS in this process (0 = library defaults); "
            "1 avoids oversubscription on small shared machines.", (0, 256), **ro))
        params.decode.min_votes = int(decl("min_votes", 2,
            "Agreeing window decodes needed before a glyph gets a cell.", (1, 100),
            apply=lambda v: setattr(params.decode, "min_votes", int(v))))
        params.decode.min_component = int(decl("min_component", 16,
            "Smallest region of mutually consistent decoded glyphs that is kept.",
            (1, 100000), apply=lambda v: setattr(params.decode, "min_component", int(v))))
        params.stereo.max_reprojection_px = float(decl("max_reprojection_px", 1.5,
            "Largest rectified reprojection error of a stereo pair (epipolar gate), px.",
            (0.01, 1000.0),
            apply=lambda v: setattr(params.stereo, "max_reprojection_px", float(v))))
        self._declare_outliers(decl, params)
        self._declare_carry(decl, params)
        self._declare_transfer(decl, params)
        self._declare_rescue(decl, params)
        self.warn_period = float(decl("warn_period", 5.0,
            "Seconds between two warnings of the same kind (throttling).", (0.0, 3600.0),
            apply=lambda v: setattr(self, "warn_period", float(v))))
        threshold = float(decl("classifier_threshold", -1.0,
            "Confidence below which a glyph's label is unknown (255), in [0, 1]; < 0 = the "
            "value stored with the weights (input=images, or unlabelled symbols).",
            (-1.0, 1.0), apply=self._set_threshold))
        params.extraction = self._extraction_params()
        diag_period = float(decl("diagnostic_period", 1.0,
            "Seconds between two DiagnosticArrays on /diagnostics (docs/diagnostics.md).",
            (0.1, 60.0), **ro))
        self.diag = DecoderDiagnostics(self._diagnostic_limits(), time.monotonic())
        from tactile_sl_decoder.calibrate.health import HealthLimits

        self.health_min_points = HealthLimits().min_points
        pattern = load_pattern_spec(pattern_file or None, allow_invalid)
        params.classifier_weights = weights or None
        params.classifier_threshold = check_threshold(threshold)
        self.pipeline = StereoPipeline(pattern, None, params)
        if self.input_mode == "images":    # fail at start, not on the first frame
            check_classifier(self.pipeline.load_classifier(), pattern.symbols,
                             weights or "(shipped)")
        touch = declare_touch(self.params)
        # the reference is prepared in a worker thread: images keep flowing meanwhile
        self.step = SensorStep(self.pipeline, touch.sensor, touch.params, background=True,
                               catch_up=CATCH_UP_BURST)
        self.sync = StereoSync(int(sync_slop * 1e9), queue_size, int(self._max_wait_s * 1e9))
        self._last_warn: dict[str, float] = {}
        self.info: dict[str, Any] = {"left": None, "right": None}
        # The newest stereo pair that arrived before any CameraInfo (messages of a frame may
        # come in any order): processed when the calibration arrives, if still fresh.
        self._waiting: tuple[float, Any, Any] | None = None
        self.stats = {"frames": 0, "skipped": 0, "dropped": 0, "points": 0, "left": 0,
                      "right": 0}
        self._proc_ms: list[float] = []

        sensor = declare_qos(self.params, "input", "the image (or symbols) and camera_info "
                             "subscriptions (depth: input_depth)", input_depth, "best_effort",
                             fixed=("depth",))
        out_qos = declare_qos(self.params, "output", "points, left|right/symbols_decoded and "
                              "the touch outputs field, wrench, contact, depth, slip", 5)
        self.pub_points = self.create_publisher(PointCloud2, "points", out_qos)
        self.touch = (None if self.step.touch is None else
                      TouchOutputs(self, self.params, self.step.touch, self.frame_prefix,
                                   out_qos))
        self.pub_sym = {}
        if self.publish_symbols and SymbolArray is not None:
            for side in ("left", "right"):
                self.pub_sym[side] = self.create_publisher(
                    SymbolArray, f"{side}/symbols_decoded", out_qos)
        # ignore[misc] below: mypy cannot infer the type of a lambda with a default (s=side)
        for side in ("left", "right"):
            self.create_subscription(
                CameraInfo, f"{side}/camera_info",
                lambda m, s=side: self._on_info(s, m),  # type: ignore[misc]  # s=side
                sensor)
            if self.input_mode == "images":
                self.create_subscription(
                    Image, f"{side}/image_raw",
                    lambda m, s=side: self._on_frame(s, m),  # type: ignore[misc]  # s=side
                    sensor)
            else:
                if SymbolArray is None:
                    raise RuntimeError("tactile_sl_msgs is not built: input=symbols unavailable")
                self.create_subscription(
                    SymbolArray, f"{side}/symbols",
                    lambda m, s=side: self._on_frame(s, m),  # type: ignore[misc]  # s=side
                    sensor)
        self.create_timer(10.0, self._report)
        # Calibration health (calibrate/health.py) is judged on the first frame decoded in
        # both images after start, a tare, a change of mirrored or of the CameraInfo: the
        # frame the touch reference is taken from (the pad untouched).
        self._health_pending = True
        self._info_key: dict[str, tuple] = {}
        self._tares_seen = 0
        self.diagnostics = DiagnosticsPublisher(
            self, self._diagnostic_statuses, diag_period,
            self.frame_prefix.strip("_/") or self.get_namespace().strip("/") or self.get_name(),
            declare_qos(self.params, "diagnostics", "/diagnostics", 10))
        self.get_logger().info(
            f"decoder ready: input={self.input_mode}, pattern {pattern.array.shape[0]}x"
            f"{pattern.array.shape[1]} (window {pattern.window[0]}x{pattern.window[1]}, "
            f"h={pattern.min_hamming}), mirrored={params.decode.mirrored}")

    def destroy_node(self) -> None:
        """Stop the pipeline's worker threads before the node goes."""
        self.step.close()
        super().destroy_node()

    def _extraction_params(self) -> Any:
        """One live ``extraction.<field>`` parameter per ExtractionParams field.

        Same meanings, defaults and ranges as the symbol_extractor node's parameters.
        """
        return declare_extraction(self.params, "extraction.", self._set_extraction,
                                  "Glyph extraction (input=images): ")

    def _declare_outliers(self, decl: Any, params: PipelineParams) -> None:
        """Live ``outliers.<field>`` parameters: the surface test of the stereo stage."""
        self._declare_group(decl, "outliers", params.outliers, "Surface outlier test "
                            "(docs/robustness.md): ", [
            ("enabled", "drop points that leave the surface their lattice neighbours "
             "define.", None),
            ("min_tolerance_m", "floor of a point's residual tolerance, m.", (1e-6, 0.01)),
            ("mad_factor", "tolerance in robust standard deviations of the frame's "
             "residuals.", (0.5, 100.0)),
            ("local_factor", "... or this many times the neighbours' median residual.",
             (0.5, 100.0)),
            ("passes", "repeat with the dropped points removed, at most this often.",
             (1, 50))])

    def _declare_carry(self, decl: Any, params: PipelineParams) -> None:
        """Live ``carry.<field>`` parameters: labels kept from the previous frame."""
        self._declare_group(decl, "carry", params.carry, "Labels carried from the previous "
                            "frame (input=images; docs/decoder.md, 'Temporal coherence'): ", [
            ("enabled", "a glyph where a glyph was one frame earlier, looking the same, "
             "keeps its label instead of being classified again (off: every glyph is "
             "classified every frame).", None),
            ("radius", "largest distance from the previous glyph's predicted position, in "
             "glyph spacings.", (0.05, 0.5)),
            ("min_correlation", "smallest correlation of the two glyph patches.",
             (0.5, 1.0)),
            ("min_confidence", "smallest confidence of the label carried.", (0.0, 1.0)),
            ("refresh_frames", "every glyph is classified again after at most this many "
             "frames, and every frame decoded in full after at most this many.", (1, 1000)),
            ("cells", "cells too: when this frame's lattice and labels confirm the cell of "
             "every glyph matched to the previous frame, the window search is skipped.",
             None)])

    def _declare_transfer(self, decl: Any, params: PipelineParams) -> None:
        """Live ``transfer.<field>`` parameters: cells carried across the stereo pair."""
        self._declare_group(decl, "transfer", params.transfer, "Cells across the stereo pair "
                            "(docs/robustness.md, 'Cells across the stereo pair'): ", [
            ("enabled", "a glyph one image could not decode takes the cell the other image "
             "decoded where the pair's geometry and the neighbouring cells put it.", None),
            ("radius", "largest distance of that glyph from the predicted place (and spread "
             "of the neighbours' predictions), in glyph spacings.", (0.01, 0.45)),
            ("clearance", "no other glyph may lie this close to it, in glyph spacings.",
             (0.1, 1.0)),
            ("min_neighbours", "neighbouring cells decoded in both images needed to predict "
             "the place.", (1, 8)),
            ("passes", "growth passes (each adds cells next to the last ones; 0 = off).",
             (0, 64))])

    def _declare_rescue(self, decl: Any, params: PipelineParams) -> None:
        """Live ``rescue.<field>`` parameters: glyphs one image did not detect."""
        self._declare_group(decl, "rescue", params.rescue, "Glyphs one camera did not "
                            "detect (input=images; docs/robustness.md, 'Glyphs one camera "
                            "did not detect'): ", [
            ("enabled", "a cell the other image decoded where this image found no glyph is "
             "measured in this image where the neighbouring cells put it.", None),
            ("radius", "largest move of the measured centre from that place (and spread of "
             "the neighbours' predictions), in glyph spacings.", (0.01, 0.45)),
            ("clearance", "no detected glyph may lie this close to the place, in glyph "
             "spacings.", (0.1, 1.0)),
            ("min_neighbours", "neighbouring cells decoded in both images needed to predict "
             "the place.", (1, 8)),
            ("min_contrast", "ink contrast needed there, as a fraction of the median "
             "contrast of the detected glyphs.", (0.0, 2.0)),
            ("centroid_passes", "grey-centroid passes, each re-sampling the patch around "
             "the last centre.", (1, 10)),
            ("grow_passes", "growth passes (each measures cells next to the last ones; "
             "0 = off).", (0, 64))])

    def _declare_group(self, decl: Any, prefix: str, target: Any, what: str,
                       spec: list[tuple[str, str, tuple | None]]) -> None:
        """One live ``<prefix>.<field>`` parameter per entry of ``spec`` on ``target``.

        ``target`` is the params dataclass the pipeline reads (``params.<prefix>``); a change
        is written to the pipeline's own copy, so the next frame uses it.
        """
        for name, text, value_range in spec:
            kind = type(getattr(target, name))
            setattr(target, name, kind(decl(
                f"{prefix}.{name}", getattr(target, name), what + text, value_range,
                apply=lambda v, n=name, k=kind: setattr(
                    getattr(self.pipeline.params, prefix), n, k(v)))))

    def _diagnostic_limits(self) -> DiagnosticLimits:
        """One live ``diagnostics.<field>`` parameter per DiagnosticLimits threshold."""
        import dataclasses

        limits = DiagnosticLimits()
        docs = field_docs(DiagnosticLimits)
        for name, default in dataclass_fields(limits):
            setattr(limits, name, float(self.params.declare(
                f"diagnostics.{name}", float(default),
                "Diagnostics threshold: " + docs.get(name, name), (0.0, 1e6),
                # ignore: mypy cannot infer the type of a lambda with a default (n=name)
                apply=lambda v, n=name: setattr(  # type: ignore[misc]
                    self.diag.limits, n, float(v)))))
        return dataclasses.replace(limits)

    def _set_extraction(self, name: str, value: Any) -> None:
        import dataclasses

        self.pipeline.params.extraction = dataclasses.replace(
            self.pipeline.params.extraction, **{name: value})

    def _set_max_age(self, value: float) -> None:
        self._max_wait_s = float(value)
        self.sync.max_age_ns = int(float(value) * 1e9)

    def _set_threshold(self, value: float) -> None:
        threshold = check_threshold(value)
        self.pipeline.params.classifier_threshold = threshold
        classifier = self.pipeline.classifier
        if classifier is not None:
            stored = classifier.meta.get("threshold", classifier.threshold)
            classifier.threshold = float(stored if threshold is None else threshold)

    def _set_mirrored(self, value: bool) -> None:
        self.step.set_mirrored(bool(value))
        if self.touch is not None:
            self.touch.restarted()
        self._health_pending = True

    # ------------------------------------------------------------------ callbacks

    def warn(self, kind: str, text: str) -> None:
        """A warning at most once per ``warn_period`` per kind of problem."""
        now = time.monotonic()
        if now - self._last_warn.get(kind, -1e9) >= self.warn_period:
            self._last_warn[kind] = now
            self.get_logger().warning(text)

    def _on_info(self, side: str, msg: CameraInfo) -> None:
        self.info[side] = msg
        self.diag.camera_info(side)
        key = (tuple(msg.k), tuple(msg.d), tuple(msg.r), tuple(msg.p), msg.width, msg.height)
        if self._info_key.get(side) != key:
            if side in self._info_key:
                self.get_logger().info(f"{side} CameraInfo changed: the calibration health "
                                       "is checked again on the next decoded frame")
            self._info_key[side] = key
            self._health_pending = True
        if self._waiting is not None and self._calibrated():
            since, left, right = self._waiting
            self._waiting = None
            if time.monotonic() - since <= self._max_wait_s:
                self._process(left, right)
            else:
                self.stats["skipped"] += 1
                self.diag.skipped("CameraInfo came later than max_age")
                stamp = left.header.stamp
                self.warn("info-late", f"frame {stamp.sec}.{stamp.nanosec:09d} skipped: its "
                          f"CameraInfo came more than max_age ({self._max_wait_s} s) after it")

    def _calibrated(self) -> bool:
        return self.info["left"] is not None and self.info["right"] is not None

    def _on_frame(self, side: str, msg: Any) -> None:
        self.stats[side] += 1
        self.diag.message(side, time.monotonic())
        ev = self.sync.add(side, stamp_ns(msg.header), msg)
        if ev.reset:
            self.warn("time-jump", "input stamps jumped back in time (bag replayed or looped?): "
                      "stereo pairing restarted")
        for s, stamp, reason in ev.dropped:
            self.stats["dropped"] += 1
            self.diag.dropped(s)
            self.warn(f"drop-{reason}", f"dropped {s} frame {stamp / 1e9:.6f}: {reason}")
        for _, left, right in ev.pairs:
            if not self._calibrated():
                if self._waiting is not None:   # superseded: skipped, with the usual warning
                    self._process(*self._waiting[1:])
                self._waiting = (time.monotonic(), left, right)
                continue
            self._process(left, right)

    def _process(self, left_msg: Any, right_msg: Any) -> None:
        t0 = time.perf_counter()
        stamp = (int(left_msg.header.stamp.sec), int(left_msg.header.stamp.nanosec))
        camera_frame = str(left_msg.header.frame_id)
        decoded = []       # set once the frame's points exist: later errors are not its input

        def on_points(result: StereoResult) -> None:
            decoded.append(True)
            self._publish_points(result, stamp, camera_frame)

        try:
            if self.info["left"] is None or self.info["right"] is None:
                missing = [f"{s}/camera_info" for s in ("left", "right") if self.info[s] is None]
                raise PipelineInputError(f"no CameraInfo received yet on {', '.join(missing)}")
            if self.input_mode == "images":
                out = self.step.process(to_gray(left_msg), to_gray(right_msg),
                                        self.info["left"], self.info["right"], tag=stamp,
                                        camera_frame=camera_frame, on_points=on_points)
            else:
                out = self.step.process_symbols(
                    from_message(left_msg), from_message(right_msg),
                    self.info["left"], self.info["right"], tag=stamp,
                    camera_frame=camera_frame, on_points=on_points)
        except (PipelineInputError, ImageFormatError, ValueError) as exc:
            if decoded:
                raise
            self.stats["skipped"] += 1
            self.diag.skipped(str(exc))
            kind = type(exc).__name__ + str(exc).split(":")[0][:40]
            self.warn(kind, f"frame {stamp[0]}.{stamp[1]:09d} skipped: {exc}")
            return
        result = out.stereo
        if self.touch is not None:
            self.touch.publish_frame(out.touch, stamp)
        if self.pub_sym:
            for side, glyphs, src in (("left", result.left, left_msg),
                                      ("right", result.right, right_msg)):
                if self.pub_sym[side].get_subscription_count():   # built only when heard
                    self.pub_sym[side].publish(make_symbol_array(glyphs, src.header,
                                                                 self.publish_patches))
        proc_s = time.perf_counter() - t0
        self._proc_ms.append(1e3 * proc_s)
        latency_s = (self.get_clock().now().nanoseconds - stamp_ns(left_msg.header)) * 1e-9
        self.diag.frame(proc_s, latency_s, result.left, result.right, len(result.points),
                        result.rejected_pairs, result.assisted)
        if self.touch is not None and self.touch.tares != self._tares_seen:
            self._tares_seen = self.touch.tares
            self._health_pending = True
        if self._health_pending:
            self._check_calibration(result)

    def _publish_points(self, result: StereoResult, stamp: tuple[int, int],
                        camera_frame: str) -> None:
        """The frame's cloud, as soon as it exists (before the touch stage runs)."""
        self.stats["frames"] += 1
        self.stats["points"] += len(result.points)
        if len(result.points) == 0 and min(len(result.left), len(result.right)) >= 50:
            self.warn("nothing-decoded",
                      f"frame {stamp[0]}.{stamp[1]:09d}: {len(result.left)} + "
                      f"{len(result.right)} glyphs found but no cell decoded in both images; "
                      f"check pattern_file (is it the printed pattern?) and mirrored")
        if len(result.points) or self.publish_empty:
            frame_id = result.frame_id or camera_frame
            self.pub_points.publish(cloud_msg(cloud_fields(result.points, stamp, frame_id)))
        if self.touch is not None:
            self.touch.before_frame()

    def _check_calibration(self, result: StereoResult) -> None:
        """Calibration health on this (untouched) frame; logged, kept for /diagnostics."""
        from tactile_sl_decoder.calibrate.health import calibration_health
        from tactile_sl_decoder.calibrate.views import PatternTarget

        try:
            rig = self.pipeline.rig(self.info["left"], self.info["right"])
        except (PipelineInputError, ValueError):
            return
        target = PatternTarget(self.pipeline.pattern, self.pipeline.params.decode.mirrored)
        report = calibration_health(result.left, result.right, rig, target)
        if report.points < self.health_min_points and not any(
                "swapped" in p for p in report.problems):
            self.diag.calibration_waiting(f"only {report.points} cells decoded in both images "
                                          f"(needs {self.health_min_points})")
            return
        self._health_pending = False
        status = self.diag.calibration_checked(report)
        text = f"calibration health {status.level_name}: {status.message}"
        if status.level == 0:
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text + " (docs/calibration.md, tactile-sl calibrate "
                                      "--check)")

    def _diagnostic_statuses(self) -> list[Status]:
        t = self.touch
        if t is not None:
            stage = t.driver.stage
            ref = stage.reference
            pose = ref.pose if ref is not None else None
            self.diag.touch_state(
                True, ref is not None, stage.params.reference_frames,
                len(ref.cells) if ref is not None else 0,
                pose.residual_rms if pose is not None else float("nan"),
                pose.residual_max if pose is not None else float("nan"),
                t.tares, t.last_tare, stage.preparing, stage.pending,
                stage.pending_dropped)
        else:
            self.diag.touch_state(False)
        return self.diag.statuses(time.monotonic())

    def _report(self) -> None:
        if not self._proc_ms and not self.stats["skipped"]:
            return
        timing = ""
        if self._proc_ms:
            ms = np.asarray(self._proc_ms)
            timing = (f"; last period: median {np.median(ms):.1f} ms, max {ms.max():.1f} ms "
                      f"per frame")
        self.get_logger().info(
            f"received {self.stats['left']} left / {self.stats['right']} right, "
            f"{self.stats['frames']} frames decoded, {self.stats['skipped']} skipped, "
            f"{self.stats['dropped']} unpaired dropped{timing}")
        self._proc_ms = []


# ---------------------------------------------------------------------- messages


def make_symbol_array(g: Glyphs, header: Any, patches: bool = False) -> Any:
    """SymbolArray (rclpy) of labelled + decoded glyphs, with the source image's header."""
    return fill_message(SymbolArray(), g, header, with_patches=patches)


def main(args: list[str] | None = None) -> None:
    """Entry point of the ``decoder`` executable."""
    run_node(DecoderNode, "decoder", args=args)


if __name__ == "__main__":
    main()
