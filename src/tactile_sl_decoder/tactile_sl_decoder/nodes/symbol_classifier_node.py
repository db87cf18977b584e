"""``symbol_classifier``: SymbolArray with patches -> the same SymbolArray, labelled.

Topics (relative): ``symbols`` in, ``labelled_symbols`` out (tactile_sl_msgs/SymbolArray,
reliable). Each glyph gets the CNN's label and its softmax confidence; below ``threshold``
the label is 255 (unknown), for the decoder to correct. Parameters in
config/symbol_classifier.yaml (``threshold`` and ``keep_patches`` apply live).
A message without patches, or with patches of another size
than the network's 18x18, or with inconsistent arrays, is skipped with a warning.
"""
from __future__ import annotations

import time

from rclpy.node import Node

from tactile_sl_common.nodes.parameters import LiveParameters, declare_qos
from tactile_sl_common.nodes.runner import run_node
from tactile_sl_decoder.classify.classifier import Classifier
from tactile_sl_decoder.contract import PATCH_SIZE
from tactile_sl_decoder.cpu_threads import set_cpu_threads
from tactile_sl_decoder.symbol_array import SymbolArrayError, fill_message, from_message
from tactile_sl_msgs.msg import SymbolArray


class SymbolClassifierNode(Node):
    """Labels incoming glyph patches with the shipped (or a given) LeNet."""

    def __init__(self) -> None:
        super().__init__("symbol_classifier")
        live = LiveParameters(self)
        weights = str(live.declare(
            "weights", "", "Weights file from `tactile-sl train`; empty = the shipped ones.",
            read_only=True)) or None
        threshold = float(live.declare(
            "threshold", -1.0, "Confidence below which the label is 255, in [0, 1]; < 0 = the "
            "value stored with the weights (0.9 for the shipped ones).", (-1.0, 1.0),
            apply=self._set_threshold))
        self.keep_patches = bool(live.declare(
            "keep_patches", False, "Forward the patches (debugging); the decoder does not "
            "need them.", apply=lambda v: setattr(self, "keep_patches", bool(v))))
        threads = int(live.declare(
            "threads", 1, "BLAS threads for inference (1 meets the budget on one core).",
            (1, 256), read_only=True))
        set_cpu_threads(threads)
        self.classifier = Classifier.load(weights)
        self.stored_threshold = float(self.classifier.threshold)
        self._set_threshold(threshold)
        self.pub = self.create_publisher(SymbolArray, "labelled_symbols", declare_qos(
            live, "output", "the labelled_symbols publisher", 10))
        # Depth 1: only the newest frame waits when the node falls behind (latency).
        self.sub = self.create_subscription(SymbolArray, "symbols", self.on_symbols, declare_qos(
            live, "input", "the symbols subscription", 1))
        self.get_logger().info(f"classifier {self.classifier.meta.get('arch')} with "
                               f"{self.classifier.classes} classes, threshold "
                               f"{self.classifier.threshold:.2f}")

    def _set_threshold(self, value: float) -> None:
        self.classifier.threshold = float(self.stored_threshold if value < 0 else value)

    def on_symbols(self, msg: SymbolArray) -> None:
        """Classify and republish; unusable messages are logged and skipped."""
        try:
            glyphs = from_message(msg)
        except SymbolArrayError as exc:
            self.get_logger().warning(f"skipping SymbolArray: {exc}", throttle_duration_sec=5.0)
            return
        if len(glyphs) and glyphs.patches is None:
            self.get_logger().warning("skipping SymbolArray without patches (set the "
                                      "extractor's publish_patches)", throttle_duration_sec=5.0)
            return
        if glyphs.patches is not None and glyphs.patches.shape[1] != PATCH_SIZE:
            self.get_logger().warning(f"skipping SymbolArray with {glyphs.patches.shape[1]} px "
                                      f"patches; the network takes {PATCH_SIZE} px",
                                      throttle_duration_sec=5.0)
            return
        start = time.perf_counter()
        if len(glyphs):
            assert glyphs.patches is not None   # refused above when glyphs came without
            glyphs.label, glyphs.confidence = self.classifier.predict(glyphs.patches)
        self.pub.publish(fill_message(SymbolArray(), glyphs, header=msg.header,
                                      with_patches=self.keep_patches))
        self.get_logger().debug(f"{len(glyphs)} glyphs in "
                                f"{1000 * (time.perf_counter() - start):.2f} ms")


def main(args: list[str] | None = None) -> None:
    """Entry point of the ``symbol_classifier`` executable (bad weights: one clear line)."""
    run_node(SymbolClassifierNode, "symbol_classifier", (Exception,), args)


if __name__ == "__main__":
    main()
