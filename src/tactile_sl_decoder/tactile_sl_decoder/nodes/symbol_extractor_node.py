"""``symbol_extractor``: Image -> SymbolArray (glyph centres, areas, spacing, 18x18 patches).

Topics (relative, remap as needed): ``image`` in (sensor_msgs/Image, sensor-data QoS;
mono8, bgr8, rgb8 ...), ``symbols`` out (tactile_sl_msgs/SymbolArray, reliable, labels 255
and cells -1 until the classifier and decoder fill them). Parameters mirror
:class:`tactile_sl_decoder.extraction.ExtractionParams` (see config/symbol_extractor.yaml).
A message that cannot be used (unsupported encoding, empty or truncated image) is skipped
with a throttled warning; the node never dies on input.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Any

import cv2
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import Image

from tactile_sl_camera.images import ImageFormatError, to_gray
from tactile_sl_camera.nodes.runner import run_node
from tactile_sl_decoder.extraction import ExtractionParams, extract_symbols
from tactile_sl_decoder.symbol_array import Symbols, fill_message
from tactile_sl_msgs.msg import SymbolArray

PARAM_DOCS = {
    "block_size": "Adaptive-threshold window side, px (odd; ~1.5-2 glyph spacings).",
    "offset": "Grey levels below the local mean that count as ink.",
    "dark_glyphs": "Ink darker than the pad (false: bright glyphs).",
    "open_size": "Side of the erosion-then-dilation kernel, px (<= 1: none).",
    "min_area_px": "Regions smaller than this are never glyphs, px^2.",
    "min_area_ratio": "Regions below this fraction of the typical glyph area are noise.",
    "split_ratio": "Regions of at least this many typical areas hold two linked glyphs.",
    "triple_ratio": "Regions of at least this many typical areas hold three linked glyphs.",
    "max_area_ratio": "Regions above this many typical areas are dropped.",
    "split_iterations": "Nearest-seed refinement passes for split regions.",
    "reject_border": "Drop regions touching the image border (cut glyphs).",
    "patch_size": "Patch side, px (the classifier expects 18).",
    "patch_span": "Patch side in local glyph spacings.",
    "default_spacing_px": "Spacing assumed when fewer than two glyphs are found, px.",
    "refine": "Refine single-glyph centres to the grey-weighted centroid of their patch.",
}


def declare_dataclass_params(node: Node, defaults: Any, docs: dict[str, str]) -> Any:
    """Declare one ROS parameter per dataclass field and return the filled dataclass."""
    values = {}
    for f in dataclasses.fields(defaults):
        default = getattr(defaults, f.name)
        node.declare_parameter(f.name, default,
                               ParameterDescriptor(description=docs.get(f.name, "")))
        value = node.get_parameter(f.name).value
        values[f.name] = type(default)(value)
    return dataclasses.replace(defaults, **values)


class SymbolExtractorNode(Node):
    """Runs :func:`extract_symbols` on every image and publishes the glyph candidates."""

    def __init__(self) -> None:
        super().__init__("symbol_extractor")
        self.params = declare_dataclass_params(self, ExtractionParams(), PARAM_DOCS)
        self.declare_parameter("publish_patches", True, ParameterDescriptor(
            description="Send the 18x18 patches (the classifier node needs them)."))
        self.publish_patches = bool(self.get_parameter("publish_patches").value)
        self.declare_parameter("threads", 1, ParameterDescriptor(
            description="OpenCV threads (1: one image uses one core; run one node per camera)."))
        cv2.setNumThreads(max(1, int(self.get_parameter("threads").value)))
        self.pub = self.create_publisher(SymbolArray, "symbols", QoSProfile(depth=10))
        self.sub = self.create_subscription(Image, "image", self.on_image,
                                            qos_profile_sensor_data)
        self.count = 0
        self.busy = 0.0

    def on_image(self, msg: Image) -> None:
        """Extract and publish; bad input is logged and skipped."""
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
        sym = Symbols.from_detections(det, gray.shape, with_patches=self.publish_patches)
        out = fill_message(SymbolArray(), sym, header=msg.header)
        self.pub.publish(out)
        self.busy += time.perf_counter() - start
        self.count += 1
        if self.count % 100 == 0:
            self.get_logger().debug(f"{self.count} images, "
                                    f"{1000 * self.busy / self.count:.2f} ms each")


def main(args: list[str] | None = None) -> None:
    """Entry point of the ``symbol_extractor`` executable."""
    run_node(SymbolExtractorNode, "symbol_extractor", args=args)


if __name__ == "__main__":
    main()
