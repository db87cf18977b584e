"""``symbol_extractor``: Image -> SymbolArray (glyph centres, areas, spacing, 18x18 patches).

Topics (relative, remap as needed): ``image`` in (sensor_msgs/Image, sensor-data QoS;
mono8, bgr8, rgb8 ...), ``symbols`` out (tactile_sl_msgs/SymbolArray, reliable, labels 255
and cells -1 until the classifier and decoder fill them). Parameters mirror
:class:`~tactile_sl_decoder.extract.extraction.ExtractionParams` (config/symbol_extractor.yaml),
with ranges, applied live (``patch_size`` and ``threads`` at start only). ``max_rate``
(0: every image) takes at most that many images per second, chosen by stamp
(:class:`~tactile_sl_decoder.frames.StampThrottle`), so the two cameras' extractors of a
stage chain on a machine too slow for the camera rate take the same frames.
A message that cannot be used (unsupported encoding, empty or truncated image) is skipped
with a throttled warning; the node never dies on input.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Any

import cv2
from rclpy.node import Node
from sensor_msgs.msg import Image

from tactile_sl_common.images import ImageFormatError, to_gray
from tactile_sl_common.nodes.parameters import LiveParameters, declare_qos
from tactile_sl_common.nodes.runner import run_node
from tactile_sl_decoder.extract.extraction import (
    EXTRACTION_SETTINGS,
    ExtractionParams,
    extract_symbols,
)
from tactile_sl_decoder.frames import StampThrottle, stamp_ns
from tactile_sl_decoder.glyphs import Glyphs
from tactile_sl_decoder.symbol_array import fill_message
from tactile_sl_msgs.msg import SymbolArray


class SymbolExtractorNode(Node):
    """Runs :func:`extract_symbols` on every image and publishes the glyph candidates."""

    def __init__(self) -> None:
        super().__init__("symbol_extractor")
        self.live = LiveParameters(self)
        self.params = self.live.declare_table(EXTRACTION_SETTINGS, ExtractionParams(),
                                              apply=self._set_extraction,
                                              current=lambda: self.params)
        self.publish_patches = bool(self.live.declare(
            "publish_patches", True, "Send the 18x18 patches (the classifier node needs them).",
            apply=lambda v: setattr(self, "publish_patches", bool(v))))
        self.throttle = StampThrottle(float(self.live.declare(
            "max_rate", 0.0, "Images per second at most, chosen by header stamp (0: every "
            "image). Both cameras' extractors take the same frames, so a stage chain on a "
            "machine too slow for the camera rate keeps whole stereo pairs for the decoder.",
            (0.0, 1000.0), apply=lambda v: setattr(self.throttle, "max_rate", float(v)))))
        self.throttled = 0
        threads = int(self.live.declare(
            "threads", 1, "OpenCV threads (1: one image uses one core; run one node per "
            "camera).", (1, 256), read_only=True))
        cv2.setNumThreads(threads)
        self.pub = self.create_publisher(SymbolArray, "symbols", declare_qos(
            self.live, "output", "the symbols publisher", 10))
        # Depth 1 (sensor data, newest only): when the node falls behind the middleware
        # replaces the waiting image instead of queueing old ones (latency, bench_graph).
        self.sub = self.create_subscription(Image, "image", self.on_image, declare_qos(
            self.live, "input", "the image subscription", 1, "best_effort"))
        self.count = 0
        self.busy = 0.0

    def _set_extraction(self, name: str, value: Any) -> None:
        self.params = dataclasses.replace(self.params, **{name: value})

    def on_image(self, msg: Image) -> None:
        """Extract and publish; bad input is logged and skipped."""
        if not self.throttle.accept(stamp_ns(msg.header)):
            self.throttled += 1
            return
        try:
            gray = to_gray(msg)
        except (ImageFormatError, ValueError) as exc:
            self.get_logger().warning(f"skipping image: {exc}", throttle_duration_sec=5.0)
            return
        start = time.perf_counter()
        try:
            det = extract_symbols(gray, self.params)
        except ValueError as exc:
            self.get_logger().warning(f"skipping image: {exc}", throttle_duration_sec=5.0)
            return
        out = fill_message(SymbolArray(), Glyphs.from_detections(det, gray.shape),
                           header=msg.header, with_patches=self.publish_patches)
        self.pub.publish(out)
        self.busy += time.perf_counter() - start
        self.count += 1
        if self.count % 100 == 0:
            self.get_logger().debug(f"{self.count} images, "
                                    f"{1000 * self.busy / self.count:.2f} ms each, "
                                    f"{self.throttled} left out by max_rate")


def main(args: list[str] | None = None) -> None:
    """Entry point of the ``symbol_extractor`` executable."""
    run_node(SymbolExtractorNode, "symbol_extractor", args=args)


if __name__ == "__main__":
    main()
