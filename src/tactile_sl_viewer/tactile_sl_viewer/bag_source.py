"""A recorded bag for the page (``tactile-sl view BAG.mcap``): one frame at a time, any order.

A bag recorded from a running sensor carries the decoder's outputs (``points``, ``field``,
``wrench``, ``contact``, ``depth``, ``slip``, ``left/symbols_decoded``): they are shown as
recorded.  A bag of camera images only (the bundled ones, a capture) is decoded here first,
frame by frame in order, with the decoder's own pipeline and touch stage (what the node and
``tactile-sl replay`` run), so the page shows what the live graph would have published.
Only the outputs stay in memory (as recorded CDR, or the decoder's small arrays); a left
image is read from the bag when its frame is shown.
"""
from __future__ import annotations

import threading
from pathlib import Path
from typing import Any, Callable, Iterator

from mcap.reader import make_reader

from tactile_sl_common.bag_io import BagError, BagReader, header_stamp_of_cdr
from tactile_sl_common.clouds import cloud_fields
from tactile_sl_common.images import ImageFormatError, to_gray
from tactile_sl_decoder.checks import check_classifier, load_pattern_spec
from tactile_sl_decoder.frames import bag_frames, bag_topics
from tactile_sl_decoder.glyphs import PipelineInputError
from tactile_sl_decoder.pipeline import PipelineParams, StereoPipeline
from tactile_sl_decoder.sensor_step import SensorStep
from tactile_sl_decoder.symbol_array import to_fields
from tactile_sl_decoder.touch.messages import header, touch_messages
from tactile_sl_decoder.touch.sensor import load_sensor
from tactile_sl_decoder.touch.stage import TouchParams

from .assembly import FrameAssembler
from .view_model import as_message

OUTPUT_TOPICS = {"points": "points", "field": "field", "wrench": "wrench",
                 "contact": "contact", "depth": "depth", "slip": "slip",
                 "glyphs": "left/symbols_decoded"}
"""Frame part -> topic (relative to the bag's namespace) of the decoder's outputs."""


class BagSource:
    """The frames of one bag, shown one at a time through a :class:`FrameAssembler`."""

    def __init__(self, path: str | Path, namespace: str = "/tactile", decode: str = "auto",
                 decoder_options: dict[str, Any] | None = None,
                 progress: Callable[[int, int], None] | None = None) -> None:
        """``decode``: 'auto' (when the bag has no recorded outputs), 'always' or 'never'."""
        self.reader = BagReader(path)
        self.path = self.reader.path
        self.namespace = "/" + namespace.strip("/")
        topics = bag_topics(self.namespace)
        self.image_topic = topics["left_image"]
        self.reader.require_topics([self.image_topic])
        self.assembler = FrameAssembler(keep=2, grace_s=0.0)
        self._lock = threading.Lock()
        self._log_time: dict[int, int] = {}            # left image stamp -> its log time
        for raw in self.reader.raw_messages([self.image_topic]):
            sec, nanosec = header_stamp_of_cdr(raw.data)
            self._log_time[int(sec) * 1_000_000_000 + int(nanosec)] = raw.log_time_ns
        self.stamps = sorted(self._log_time)
        if not self.stamps:
            raise BagError(f"{self.path}: no images on {self.image_topic}")
        recorded = {part: f"{self.namespace}/{topic}" for part, topic in OUTPUT_TOPICS.items()
                    if f"{self.namespace}/{topic}" in self.reader.topics}
        if decode not in ("auto", "always", "never"):
            raise ValueError(f"decode must be auto, always or never, got {decode!r}")
        self.decoded_here = decode == "always" or (decode == "auto" and not recorded)
        self._outputs: dict[int, dict[str, Any]] = {}
        if self.decoded_here:
            for stamp, parts in decode_bag(self.path, self.namespace, decoder_options or {},
                                           len(self.stamps), progress):
                self._outputs[stamp] = parts
        else:
            self._read_recorded(recorded)
        self.index = -1
        self.seek(0)

    def _read_recorded(self, recorded: dict[str, str]) -> None:
        """Every recorded output, by header stamp (decoded with the bag's own schemas)."""
        part_of = {topic: part for part, topic in recorded.items()}
        for raw, msg in self.reader.messages(list(recorded.values())):
            stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
            self._outputs.setdefault(stamp, {})[part_of[raw.topic]] = msg

    @property
    def frame_rate(self) -> float:
        """Stereo frames per second of the recording (10 when it cannot tell)."""
        span = (self.stamps[-1] - self.stamps[0]) * 1e-9
        return (len(self.stamps) - 1) / span if len(self.stamps) > 1 and span > 0 else 10.0

    def _left_image(self, stamp: int) -> Any:
        log_time = self._log_time[stamp]
        with open(self.path, "rb") as f:
            for schema, _channel, message in make_reader(f).iter_messages(
                    topics=[self.image_topic], starting_at=log_time, ending_before=log_time + 1):
                if schema is not None and \
                        header_stamp_of_cdr(message.data) == divmod(stamp, 1_000_000_000):
                    return self.reader.decoder(schema)(message.data)
        return None

    # ------------------------------------------------------------------ FrameSource

    def hello(self) -> dict[str, Any]:
        return {"mode": "bag", "bag": self.path.name, "frames": len(self.stamps),
                "rate": self.frame_rate, "namespace": self.namespace,
                "decoded_here": self.decoded_here,
                "slip": any("slip" in parts for parts in self._outputs.values())}

    def seek(self, index: int) -> None:
        """Show frame ``index`` (clamped to the bag)."""
        index = max(0, min(int(index), len(self.stamps) - 1))
        with self._lock:
            if index == self.index:
                return
            self.index = index
            stamp = self.stamps[index]
            image = self._left_image(stamp)
            self.assembler.reset()
            for part, msg in self._outputs.get(stamp, {}).items():
                self.assembler.add(part, msg, stamp)
            if image is not None:
                self.assembler.add("image", image, stamp)

    def extra(self) -> dict[str, Any]:
        index = self.index
        return {"bag": {"index": index, "count": len(self.stamps),
                        "time_s": (self.stamps[index] - self.stamps[0]) * 1e-9}}


def decode_bag(path: Path, namespace: str, options: dict[str, Any], total: int,
               progress: Callable[[int, int], None] | None = None
               ) -> Iterator[tuple[int, dict[str, Any]]]:
    """(stamp, {part: message}) of every frame, decoded as the ``decoder`` node would.

    ``options``: ``pattern``, ``classifier``, ``sensor`` (files; None = shipped),
    ``mirrored``, ``reference_frames``.  A frame the pipeline refuses is left without
    outputs (its image is still shown).
    """
    mirrored = bool(options.get("mirrored", False))
    pattern = load_pattern_spec(options.get("pattern"))
    params = PipelineParams(classifier_weights=options.get("classifier"))
    params.decode.mirrored = mirrored
    pipeline = StereoPipeline(pattern, None, params)
    try:
        check_classifier(pipeline.load_classifier(), pattern.symbols,
                         options.get("classifier") or "(shipped)")
        sensor = load_sensor(options.get("sensor"))
        step = SensorStep(pipeline, sensor,
                          TouchParams(reference_frames=int(options.get("reference_frames", 1))))
        for i, frame in enumerate(bag_frames(path, namespace, ground_truth=False)):
            if progress is not None:
                progress(i + 1, total)
            try:
                if frame.left_info is None or frame.right_info is None:
                    raise PipelineInputError("no camera_info for this frame")
                out = step.process(to_gray(frame.left_image), to_gray(frame.right_image),
                                   frame.left_info, frame.right_info)
            except (PipelineInputError, ImageFormatError):
                continue
            result = out.stereo
            frame_id = result.frame_id or str(frame.left_image.header.frame_id)
            parts: dict[str, Any] = {
                "points": as_message(cloud_fields(result.points, frame.stamp, frame_id)),
                "glyphs": as_message(to_fields(result.left, header(frame.stamp, frame_id),
                                               with_patches=False))}
            if out.touch.result is not None:   # offline: no backlog, every frame in line
                for name, _schema, fields in touch_messages(out.touch.result, frame.stamp,
                                                            sensor.pad_frame):
                    parts[name] = as_message(fields)
            yield frame.stamp_ns, parts
    finally:
        pipeline.close()
