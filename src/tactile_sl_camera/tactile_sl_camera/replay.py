"""
Bag replay without ROS: which topics to play, under which names, and when.

The ``replay`` node only publishes what :class:`ReplayPlan` yields, so the selection,
renaming, pacing and restamping rules are tested here without a ROS graph.
"""
from __future__ import annotations

import os
import statistics
from dataclasses import dataclass
from typing import Callable, Iterable, Iterator

from tactile_sl_common.bag_io import (
    BagError,
    BagReader,
    header_stamp_of_cdr,
    ns_to_stamp,
    restamp_cdr,
    stamp_to_ns,
)

IMAGE_TYPE = "sensor_msgs/msg/Image"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
DEFAULT_TYPES = (IMAGE_TYPE, CAMERA_INFO_TYPE)
ONE_FRAME_LOOP_PERIOD_NS = 100_000_000
"""A bag of one stereo frame has no recorded rate: looped, it plays at 10 Hz x ``rate``
(the bundled bags' rate) rather than publishing as fast as the thread can spin."""
HEADER_FIRST_TYPES = {IMAGE_TYPE, CAMERA_INFO_TYPE, "sensor_msgs/msg/PointCloud2",
                      "sensor_msgs/msg/CompressedImage", "tactile_sl_msgs/msg/SymbolArray"}


@dataclass(frozen=True)
class ReplayItem:
    """One message to publish: relative topic name, type, CDR bytes and due time.

    ``due_s`` is seconds after the start of this pass, already divided by the rate
    (0 when playing as fast as possible).
    """

    topic: str
    schema_name: str
    data: bytes
    due_s: float
    stamp_ns: int
    loop_index: int


def relative_name(bag_topic: str, bag_namespace: str) -> str:
    """
    ``/tactile/left/image_raw`` -> ``left/image_raw`` for namespace ``/tactile``.

    Publishing under relative names lets a user namespace or remap the replay like any node.
    """
    ns = "/" + bag_namespace.strip("/") if bag_namespace.strip("/") else ""
    if ns and bag_topic.startswith(ns + "/"):
        return bag_topic[len(ns) + 1:]
    return bag_topic.lstrip("/")


class ReplayPlan:
    """
    Selects topics of a bag and produces the publication schedule.

    rate > 0 plays at ``rate`` times the recorded speed; rate == 0 plays as fast as the
    consumer of the iterator goes (the node adds subscriber pacing on top).
    Stamps are left as recorded; :class:`Restamper` replaces them at publication time.
    """

    def __init__(self, bag_path: str | os.PathLike, topics: Iterable[str] = (),
                 bag_namespace: str = "/tactile", rate: float = 1.0) -> None:
        if rate < 0:
            raise ValueError(f"rate must be >= 0 (0 = as fast as possible), got {rate}")
        self.reader = BagReader(bag_path)
        self.rate = float(rate)
        self.bag_namespace = bag_namespace
        wanted = [t for t in topics if t]
        if wanted:
            absolute = [t if t.startswith("/") else self._absolute(t) for t in wanted]
            self.reader.require_topics(absolute)
            self.bag_topics = absolute
        else:
            self.bag_topics = sorted(
                t.name for t in self.reader.topics.values()
                if t.schema_name in DEFAULT_TYPES)
            if not self.bag_topics:
                have = ", ".join(f"{t.name} [{t.schema_name}]"
                                 for t in self.reader.topics.values()) or "none"
                raise BagError(f"{self.reader.path}: no sensor_msgs/Image or CameraInfo "
                               f"topics to replay (the bag has: {have})")
        self.outputs = {t: relative_name(t, bag_namespace) for t in self.bag_topics}
        self.types = {t: self.reader.topics[t].schema_name for t in self.bag_topics}
        # measured by the first pass played to its end (items()): ns, None until then
        self.span_ns: int | None = None             # first to last log time
        self.frame_period_ns: int | None = None     # median step between frame stamps

    def _absolute(self, relative: str) -> str:
        ns = "/" + self.bag_namespace.strip("/") if self.bag_namespace.strip("/") else ""
        return f"{ns}/{relative}"

    @property
    def message_count(self) -> int:
        return sum(self.reader.topics[t].message_count for t in self.bag_topics)

    def items(self, loop_index: int = 0) -> Iterator[ReplayItem]:
        """One pass over the bag, with each message's recorded header stamp.

        A pass played to its end also measures the bag: its span (first to last log time)
        and its frame period (median step between successive frame stamps), which
        :meth:`next_pass_start` needs to loop at the recorded rate.
        """
        start_ns: int | None = None
        last_ns = 0
        stamps: list[int] = []
        for raw in self.reader.raw_messages(self.bag_topics):
            if start_ns is None:
                start_ns = raw.log_time_ns
            last_ns = raw.log_time_ns
            due = 0.0 if self.rate == 0 else (raw.log_time_ns - start_ns) / 1e9 / self.rate
            stamp_ns = raw.log_time_ns
            if raw.schema_name in HEADER_FIRST_TYPES:
                stamp_ns = stamp_to_ns(*header_stamp_of_cdr(raw.data))
            if not stamps or stamp_ns != stamps[-1]:
                stamps.append(stamp_ns)
            yield ReplayItem(self.outputs[raw.topic], raw.schema_name, raw.data, due, stamp_ns,
                             loop_index)
        if start_ns is not None:
            frames = sorted(set(stamps))
            steps = [b - a for a, b in zip(frames, frames[1:])]
            self.span_ns = last_ns - start_ns
            self.frame_period_ns = (int(statistics.median(steps)) if steps
                                    else ONE_FRAME_LOOP_PERIOD_NS)

    def next_pass_start(self, pass_start: float, last_published: float) -> float:
        """When (clock of ``pass_start``, seconds) the next pass of a loop starts.

        One frame period (at this rate) after the last frame, as the recording would have
        gone on: ``pass_start`` + (span + period) / rate on schedule, and never less than a
        period after ``last_published`` when playing fell behind it (pacing, a slow
        machine).  Looping used to start the next pass at once, which dropped a frame
        period at every wrap (a 7-frame 10 Hz bag looped at 11.7 Hz).  At rate 0, or
        before a pass has been played to its end: ``last_published``.
        """
        if self.rate == 0 or self.span_ns is None or self.frame_period_ns is None:
            return last_published
        period = self.frame_period_ns / 1e9 / self.rate
        return max(pass_start + self.span_ns / 1e9 / self.rate + period,
                   last_published + period)


class Restamper:
    """Stamps each stereo frame with the time it is published, as a live camera would.

    Messages that share a recorded stamp (the images and camera_info of one stereo frame)
    get one and the same new stamp, taken from ``clock_ns`` when the first of them goes out;
    so pairing by exact stamps still works, and stamp-to-output latency is measurable at any
    playback rate. Use one Restamper per pass over the bag.
    """

    def __init__(self, clock_ns: Callable[[], int]) -> None:
        self.clock_ns = clock_ns
        self._recorded: int | None = None
        self._new = 0

    def __call__(self, item: ReplayItem) -> tuple[bytes, int]:
        """CDR bytes and stamp (ns) to publish for ``item``."""
        if item.schema_name not in HEADER_FIRST_TYPES:
            return item.data, item.stamp_ns
        if item.stamp_ns != self._recorded:
            self._recorded = item.stamp_ns
            self._new = int(self.clock_ns())
        return restamp_cdr(item.data, *ns_to_stamp(self._new)), self._new
