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

import dataclasses
import time
from typing import Any

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from tactile_sl_common.clouds import cloud_fields
from tactile_sl_common.heap import freeze_long_lived
from tactile_sl_common.images import ImageFormatError, to_gray
from tactile_sl_common.nodes.messages import cloud_msg
from tactile_sl_common.nodes.parameters import LiveParameters, declare_qos
from tactile_sl_common.nodes.runner import run_node
from tactile_sl_decoder.calibrate.health import HealthLimits, calibration_health
from tactile_sl_decoder.calibrate.views import PatternTarget
from tactile_sl_decoder.checks import check_classifier, check_threshold, load_pattern_spec
from tactile_sl_decoder.extract.extraction import ExtractionParams
from tactile_sl_decoder.frames import StereoSync, stamp_ns
from tactile_sl_decoder.glyphs import Glyphs, PipelineInputError
from tactile_sl_decoder.nodes.decoder_settings import (
    DECODER_TABLES,
    DecoderNodeSettings,
    ElastomerOverrides,
)
from tactile_sl_decoder.nodes.diagnostics import DecoderDiagnostics, DiagnosticLimits, Status
from tactile_sl_decoder.nodes.diagnostics_publisher import DiagnosticsPublisher
from tactile_sl_decoder.nodes.touch_outputs import CATCH_UP_BURST, TouchOutputs
from tactile_sl_decoder.pipeline import PipelineParams, StereoPipeline, StereoResult
from tactile_sl_decoder.sensor_step import SensorStep
from tactile_sl_decoder.symbol_array import fill_message, from_message
from tactile_sl_decoder.touch.driver import TouchFrame
from tactile_sl_decoder.touch.sensor import load_sensor
from tactile_sl_decoder.touch.stage import TouchParams
from tactile_sl_decoder.warm_up import warm_up

try:
    from tactile_sl_msgs.msg import SymbolArray
except ImportError:  # pragma: no cover - interfaces not built
    SymbolArray = None


WORKER_START_TIMEOUT = 120.0
HEALTH_WAIT_S = 5.0
"""Seconds the calibration health check waits for the touch reference (see
:meth:`DecoderNode._judge_calibration`)."""
"""Seconds the camera worker process may take to start before the node gives up."""


class DecoderNode(Node):
    """Runs the stereo pipeline on every synchronised stereo frame."""

    def __init__(self) -> None:
        super().__init__("decoder")
        self.live = LiveParameters(self)
        params = PipelineParams(extraction=ExtractionParams())
        self.pipeline_params = params
        self.settings = DecoderNodeSettings()
        self.limits = DiagnosticLimits()
        self.touch_params = TouchParams()
        self.overrides = ElastomerOverrides()
        self._declare_settings()
        s = self.settings
        self.input_mode, self.frame_prefix = s.input, s.frame_prefix
        params.threads, params.cpu_threads = s.threads, s.cpu_threads
        params.processes = s.camera_processes and s.input == "images"
        self.diag = DecoderDiagnostics(self.limits, time.monotonic())
        self.health_min_points = HealthLimits().min_points
        pattern = load_pattern_spec(s.pattern_file or None, s.allow_invalid_pattern)
        params.classifier_weights = s.classifier_weights or None
        params.classifier_threshold = check_threshold(s.classifier_threshold)
        self.pipeline = StereoPipeline(pattern, None, params)
        if self.input_mode == "images":    # fail at start, not on the first frame
            check_classifier(self.pipeline.load_classifier(), pattern.symbols,
                             s.classifier_weights or "(shipped)")
        sensor = (self.overrides.apply_to(load_sensor(s.sensor_file or None), s.pad_frame)
                  if s.touch else None)
        # the reference is prepared in a worker thread: images keep flowing meanwhile; the
        # touch stage runs in a thread of its own, overlapping the next frame's pipeline
        self.step = SensorStep(self.pipeline, sensor, self.touch_params, background=True,
                               catch_up=CATCH_UP_BURST, on_touch=self._on_touch,
                               on_touch_error=self._on_touch_error)
        self.sync = StereoSync(int(s.sync_slop * 1e9), s.queue_size, int(s.max_age * 1e9))
        self._last_warn: dict[str, float] = {}
        self.info: dict[str, Any] = {"left": None, "right": None}
        # The newest stereo pair that arrived before any CameraInfo (messages of a frame may
        # come in any order): processed when the calibration arrives, if still fresh.
        self._waiting: tuple[float, Any, Any] | None = None
        self.stats = {"frames": 0, "skipped": 0, "dropped": 0, "points": 0, "left": 0,
                      "right": 0}
        self._proc_ms: list[float] = []
        self._heap_frozen = False

        inputs = declare_qos(self.live, "input", "the image (or symbols) and camera_info "
                             "subscriptions (depth: input_depth)", s.input_depth,
                             "best_effort", fixed=("depth",))
        out_qos = declare_qos(self.live, "output", "points, left|right/symbols_decoded and "
                              "the touch outputs field, wrench, contact, depth, slip", 5)
        self.pub_points = self.create_publisher(PointCloud2, "points", out_qos)
        self.touch = (None if self.step.touch is None else
                      TouchOutputs(self, self.live, self.step.touch, self.frame_prefix,
                                   out_qos, self.step.poll_touch))
        self.pub_sym = {}
        if s.publish_symbols and SymbolArray is not None:
            for side in ("left", "right"):
                self.pub_sym[side] = self.create_publisher(
                    SymbolArray, f"{side}/symbols_decoded", out_qos)
        # ignore[misc] below: mypy cannot infer the type of a lambda with a default (s=side)
        for side in ("left", "right"):
            self.create_subscription(
                CameraInfo, f"{side}/camera_info",
                lambda m, s=side: self._on_info(s, m),  # type: ignore[misc]  # s=side
                inputs)
        if self.input_mode == "images":
            # Images are subscribed to once the camera worker process has started and
            # warmed up (~1-2 s; the node answers its services meanwhile): the first frames
            # would otherwise queue behind them and be lost.
            self._inputs_qos = inputs
            self._starting_since = time.monotonic()
            self._start_timer: Any = self.create_timer(0.05, self._subscribe_when_ready)
            self._subscribe_when_ready()
        else:
            if SymbolArray is None:
                raise RuntimeError("tactile_sl_msgs is not built: input=symbols unavailable")
            for side in ("left", "right"):
                self.create_subscription(
                    SymbolArray, f"{side}/symbols",
                    lambda m, s=side: self._on_frame(s, m),  # type: ignore[misc]  # s=side
                    inputs)
        self.create_timer(10.0, self._report)
        # Calibration health (calibrate/health.py) is judged on the first frame decoded in
        # both images after start, a tare, a change of mirrored or of the CameraInfo: the
        # frame the touch reference is taken from (the pad untouched).
        self._health_pending = True
        self._health_frame: tuple[float, StereoResult] | None = None   # (since, frame) due
        self._info_key: dict[str, tuple] = {}
        self._tares_seen = 0
        self.diagnostics = DiagnosticsPublisher(
            self, self._diagnostic_statuses, s.diagnostic_period,
            self.frame_prefix.strip("_/") or self.get_namespace().strip("/") or self.get_name(),
            declare_qos(self.live, "diagnostics", "/diagnostics", 10))
        self.get_logger().info(
            f"decoder ready: input={self.input_mode}, pattern {pattern.array.shape[0]}x"
            f"{pattern.array.shape[1]} (window {pattern.window[0]}x{pattern.window[1]}, "
            f"h={pattern.min_hamming}), mirrored={params.decode.mirrored}")

    def _subscribe_when_ready(self) -> None:
        """Subscribe to both cameras' images once the pipeline's workers are ready."""
        if self._start_timer is None:
            return
        if not self.pipeline.ready():
            if time.monotonic() - self._starting_since > WORKER_START_TIMEOUT:
                raise RuntimeError(f"the camera worker process did not start within "
                                   f"{WORKER_START_TIMEOUT:.0f} s")
            return
        self.destroy_timer(self._start_timer)
        self._start_timer = None
        if self.input_mode == "images":
            # the node's own decode, stereo and outlier code meet their first frame now,
            # not with the first camera frame (warm_up.py)
            started = time.perf_counter()
            try:
                points = warm_up(self.pipeline)
                self.get_logger().debug(f"warm-up frame: {points} points in "
                                        f"{1e3 * (time.perf_counter() - started):.0f} ms")
            except Exception as exc:   # best effort: then the first camera frame warms up
                self.get_logger().warning(f"warm-up frame skipped ({type(exc).__name__}: "
                                          f"{exc}); the first camera frame takes longer")
        for side in ("left", "right"):
            self.create_subscription(
                Image, f"{side}/image_raw",
                lambda m, s=side: self._on_frame(s, m),  # type: ignore[misc]  # s=side
                self._inputs_qos)
        if self.pipeline.params.processes:
            self.get_logger().info(f"camera worker process ready after "
                                   f"{time.monotonic() - self._starting_since:.1f} s: "
                                   f"subscribed to left/image_raw and right/image_raw")

    def destroy_node(self) -> None:
        """Stop the pipeline's worker threads before the node goes."""
        self.step.close()
        super().destroy_node()

    def _declare_settings(self) -> None:
        """Every parameter but QoS: one loop over the tables of nodes/decoder_settings.py.

        Each table fills its settings object, which the library reads (the pipeline's and
        the touch stage's params are these very objects), so a live change, written there
        after it was validated, applies from the next frame.
        """
        p = self.pipeline_params
        settings = {"node": self.settings, "decode": p.decode, "stereo": p.stereo,
                    "outliers": p.outliers, "carry": p.carry, "transfer": p.transfer,
                    "rescue": p.rescue, "artwork_fit": p.artwork_fit,
                    "extraction": p.extraction, "diagnostics": self.limits,
                    "touch": self.touch_params, "contact": self.touch_params.contact,
                    "touch_weights": self.touch_params.weights,
                    "elastomer": self.overrides}
        apply = {"node": self._apply_node, "decode": self._apply_decode,
                 "extraction": self._apply_extraction}
        current = {"extraction": lambda: self.pipeline_params.extraction}
        for d in DECODER_TABLES:
            self.live.declare_table(d.table, settings[d.name], d.prefix, d.what,
                                    apply.get(d.name), current.get(d.name))

    def _apply_node(self, name: str, value: Any) -> None:
        """A live change of one of the node's own settings."""
        setattr(self.settings, name, value)
        if name == "sync_slop":
            self.sync.slop_ns = int(value * 1e9)
        elif name == "queue_size":
            self.sync.queue_size = int(value)
        elif name == "max_age":
            self.sync.max_age_ns = int(value * 1e9)
        elif name == "classifier_threshold":
            self._set_threshold(value)

    def _apply_decode(self, name: str, value: Any) -> None:
        setattr(self.pipeline_params.decode, name, value)
        if name == "mirrored":
            self._set_mirrored(bool(value))

    def _apply_extraction(self, name: str, value: Any) -> None:
        """A new ExtractionParams object: an image being extracted keeps the one it had."""
        self.pipeline_params.extraction = dataclasses.replace(
            self.pipeline_params.extraction, **{name: value})

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
        self._recheck_calibration()

    # ------------------------------------------------------------------ callbacks

    def warn(self, kind: str, text: str) -> None:
        """A warning at most once per ``warn_period`` per kind of problem."""
        now = time.monotonic()
        if now - self._last_warn.get(kind, -1e9) >= self.settings.warn_period:
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
            self._recheck_calibration()
        if self._waiting is not None and self._calibrated():
            since, left, right = self._waiting
            self._waiting = None
            if time.monotonic() - since <= self.settings.max_age:
                self._process(left, right)
            else:
                self.stats["skipped"] += 1
                self.diag.skipped("CameraInfo came later than max_age")
                stamp = left.header.stamp
                self.warn("info-late", f"frame {stamp.sec}.{stamp.nanosec:09d} skipped: its "
                          f"CameraInfo came more than max_age ({self.settings.max_age} s) after it")

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
                self.pipeline.keep_patches = self.settings.publish_patches   # live setting
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
        if self.pub_sym:
            for side, glyphs, src in (("left", result.left, left_msg),
                                      ("right", result.right, right_msg)):
                if self.pub_sym[side].get_subscription_count():   # built only when heard
                    self.pub_sym[side].publish(make_symbol_array(glyphs, src.header,
                                                                 self.settings.publish_patches))
        proc_s = time.perf_counter() - t0
        if not self._heap_frozen:     # what the first frame set up lives as long as the node
            self._heap_frozen = freeze_long_lived(collect=False) > 0
        self._proc_ms.append(1e3 * proc_s)
        latency_s = (self.get_clock().now().nanoseconds - stamp_ns(left_msg.header)) * 1e-9
        self.diag.frame(proc_s, latency_s, result.left, result.right, len(result.points),
                        result.rejected_pairs, result.assisted)
        if self.touch is not None and self.touch.tares != self._tares_seen:
            self._tares_seen = self.touch.tares
            self._recheck_calibration()
        if self._health_pending:
            self._judge_calibration(result)

    def _on_touch(self, touch: TouchFrame, stamp: tuple[int, int] | None) -> None:
        """The touch worker's outputs of one frame (or of a poll: ``stamp`` None)."""
        if self.touch is not None:
            self.touch.publish_frame(touch, stamp)

    def _on_touch_error(self, exc: BaseException) -> None:
        """An error in the touch worker: said loudly, the frames go on."""
        self.get_logger().error(f"touch outputs of a frame failed: {type(exc).__name__}: "
                                f"{exc}")

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
        if len(result.points) or self.settings.publish_empty:
            frame_id = result.frame_id or camera_frame
            self.pub_points.publish(cloud_msg(cloud_fields(result.points, stamp, frame_id)))
        if self.touch is not None:
            self.touch.before_frame()

    def _recheck_calibration(self) -> None:
        """Judge the calibration again, on a frame from now on."""
        self._health_pending = True
        self._health_frame = None

    def _judge_calibration(self, result: StereoResult) -> None:
        """Calibration health on this frame, or on the first pending one once touch is ready.

        While the touch reference is taken from that frame (prepared in a thread beside the
        frames), the check waits: run then, its ~2 ms of numpy took 24-34 ms against the
        preparation's share of the interpreter lock, and held up the next frame.  It runs on
        the frame it was due on (the untouched pad), once the reference is ready or
        ``HEALTH_WAIT_S`` later (a first start computes the inversion: 1-2.5 s on two cores).
        """
        if self._health_frame is None:
            self._health_frame = (time.monotonic(), result)
        since, due = self._health_frame
        if (self.touch is not None and not self.touch.driver.ready
                and time.monotonic() - since < HEALTH_WAIT_S):
            return
        self._health_frame = None
        self._check_calibration(due)

    def _check_calibration(self, result: StereoResult) -> None:
        """Calibration health on this (untouched) frame; logged, kept for /diagnostics."""
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
