"""Stereo frames: grouping a bag's messages into frames, and pairing live left/right streams."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tactile_sl_common.bag_io import BagReader, header_stamp_of_cdr


@dataclass
class BagFrame:
    """One stereo frame of a bag: the four input messages (decoded) and ground truth."""

    stamp: tuple[int, int]
    left_image: Any
    right_image: Any
    left_info: Any
    right_info: Any
    ground_truth: Any = None

    @property
    def stamp_ns(self) -> int:
        """Stamp in nanoseconds (for sorting and keys; the message keeps the exact ints)."""
        return self.stamp[0] * 1_000_000_000 + self.stamp[1]


def bag_topics(namespace: str = "/tactile") -> dict[str, str]:
    """Topic of each frame part in a bag recorded in ``namespace``."""
    ns = namespace.rstrip("/")
    return {"left_image": f"{ns}/left/image_raw", "right_image": f"{ns}/right/image_raw",
            "left_info": f"{ns}/left/camera_info", "right_info": f"{ns}/right/camera_info",
            "ground_truth": f"{ns}/ground_truth/points"}


def count_bag_frames(path: str | Path, namespace: str = "/tactile") -> int:
    """Number of left images in a bag (for progress bars)."""
    reader = BagReader(path)
    topic = bag_topics(namespace)["left_image"]
    return reader.topics[topic].message_count if topic in reader.topics else 0


def bag_frames(path: str | Path, namespace: str = "/tactile",
               ground_truth: bool = True, camera_info: bool = True) -> Any:
    """Stereo frames of a bag, grouped by exact header stamp, in stamp order.

    Messages of one frame may come in any order; a frame is complete once both images are
    there.  CameraInfo may be sent less often than images: the latest one of each side is
    used then.  Raises ``BagError`` for unreadable bags or missing image topics, and for
    missing camera_info topics unless ``camera_info`` is False (the caller has the
    calibration from elsewhere: the frames' infos are then None where the bag has none).
    """
    reader = BagReader(path)
    topics = bag_topics(namespace)
    images = [topics["left_image"], topics["right_image"]]
    infos = [topics["left_info"], topics["right_info"]]
    reader.require_topics(images + infos if camera_info else images)
    wanted = images + [t for t in infos if camera_info or t in reader.topics]
    if ground_truth and topics["ground_truth"] in reader.topics:
        wanted.append(topics["ground_truth"])
    part_of = {v: k for k, v in topics.items()}
    pending: dict[tuple[int, int], dict[str, Any]] = {}
    latest_info: dict[str, Any] = {}

    def flush(up_to: tuple[int, int] | None) -> Any:
        for stamp in sorted(pending):
            if up_to is not None and stamp >= up_to:
                break
            parts = pending.pop(stamp)
            for side in ("left_info", "right_info"):
                if side in parts:
                    latest_info[side] = parts[side]
            if "left_image" in parts and "right_image" in parts:
                left_info = parts.get("left_info", latest_info.get("left_info"))
                right_info = parts.get("right_info", latest_info.get("right_info"))
                yield BagFrame(stamp, parts["left_image"], parts["right_image"], left_info,
                               right_info, parts.get("ground_truth"))

    for raw, msg in reader.messages(wanted):
        sec, nanosec = header_stamp_of_cdr(raw.data)
        stamp = (int(sec), int(nanosec))
        # log time = stamp in our bags, but be tolerant: only flush frames well behind.
        yield from flush(_minus(stamp, 1))
        pending.setdefault(stamp, {})[part_of[raw.topic]] = msg
    yield from flush(None)


def _minus(stamp: tuple[int, int], seconds: int) -> tuple[int, int]:
    return (stamp[0] - seconds, stamp[1])


# ---------------------------------------------------------------------- stereo pairing


@dataclass
class SyncEvent:
    """What :class:`StereoSync` decided for an incoming message."""

    pairs: list[tuple[int, Any, Any]] = field(default_factory=list)   # (stamp_ns, left, right)
    dropped: list[tuple[str, int, str]] = field(default_factory=list)  # (side, stamp, reason)
    reset: bool = False            # time jumped back by more than max_age: state cleared


def stamp_ns(header: Any) -> int:
    """A message header's stamp as integer nanoseconds (exact), as the syncs below take it."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


class StereoSync:
    """Pairs left/right messages by header stamp: exact stamps first, then within a slop.

    Unpaired messages wait in bounded per-side queues; a message older than the newest
    paired frame, or pushed out of a full queue, or older than ``max_age_ns`` behind the
    newest message seen, is dropped (stale frames are never queued without bound).  A stamp
    more than ``max_age_ns`` *before* the last paired frame means time jumped back (a bag
    played again): the state is reset rather than every later frame dropped as stale.
    """

    def __init__(self, slop_ns: int = 0, queue_size: int = 5, max_age_ns: int = 500_000_000):
        self.slop_ns = int(slop_ns)
        self.queue_size = max(1, int(queue_size))
        self.max_age_ns = int(max_age_ns)
        self.pending: dict[str, dict[int, Any]] = {"left": {}, "right": {}}
        self.last_paired_ns: int | None = None
        self.newest_ns: int | None = None

    def add(self, side: str, stamp_ns: int, item: Any) -> SyncEvent:
        """Offer one message; returns the pairs completed and the messages dropped."""
        ev = SyncEvent()
        other = "right" if side == "left" else "left"
        if self.last_paired_ns is not None and stamp_ns < self.last_paired_ns - self.max_age_ns:
            # Time jumped back by more than max_age (a bag played again, a looping replay,
            # a restarted camera clock): start over instead of dropping everything.
            for s in ("left", "right"):
                for old in self.pending[s]:
                    ev.dropped.append((s, old, "time jumped back (sync reset)"))
                self.pending[s].clear()
            self.last_paired_ns = None
            self.newest_ns = None
            ev.reset = True
        if self.last_paired_ns is not None and stamp_ns <= self.last_paired_ns:
            ev.dropped.append((side, stamp_ns, "stale (not newer than the last frame)"))
            return ev
        self.newest_ns = stamp_ns if self.newest_ns is None else max(self.newest_ns, stamp_ns)
        mine, theirs = self.pending[side], self.pending[other]
        partner: int | None = stamp_ns if stamp_ns in theirs else None
        if partner is None and self.slop_ns > 0 and theirs:
            cand = min(theirs, key=lambda s: abs(s - stamp_ns))
            if abs(cand - stamp_ns) <= self.slop_ns and cand not in mine:
                partner = cand
        if partner is not None:
            other_item = theirs.pop(partner)
            stamp = stamp_ns if side == "left" else partner   # the left image's stamp
            left, right = (item, other_item) if side == "left" else (other_item, item)
            ev.pairs.append((stamp, left, right))
            self.last_paired_ns = max(stamp_ns, partner)
            for s in ("left", "right"):                          # older ones are now stale
                for old in [t for t in self.pending[s] if t <= self.last_paired_ns]:
                    del self.pending[s][old]
                    ev.dropped.append((s, old, "no stereo partner (unsynchronised)"))
            return ev
        mine[stamp_ns] = item
        while len(mine) > self.queue_size:
            old = min(mine)
            del mine[old]
            ev.dropped.append((side, old, "no stereo partner before the queue filled"))
        for s in ("left", "right"):
            for old in [t for t in self.pending[s] if t < self.newest_ns - self.max_age_ns]:
                del self.pending[s][old]
                ev.dropped.append((s, old, "no stereo partner in time (unsynchronised)"))
        return ev


class StampThrottle:
    """At most ``max_rate`` frames per second, chosen by header stamp, not by arrival.

    A frame is taken when its stamp falls in another slot of ``1 / max_rate`` seconds
    (rounded to whole nanoseconds; integer arithmetic, so both cameras' nodes agree exactly)
    than the last frame taken. The two cameras of a stereo pair
    carry equal stamps (the contract's convention), so two nodes throttling each camera's
    stream on their own take the *same* frames: an overloaded stage chain keeps whole
    stereo pairs instead of dropping frames on each side independently, which the decoder
    then cannot pair. ``max_rate`` 0 takes every frame. A stamp that goes back (a bag played
    again) starts over.
    """

    def __init__(self, max_rate: float = 0.0) -> None:
        self.max_rate = float(max_rate)
        self._last_slot: int | None = None

    def accept(self, stamp_ns: int) -> bool:
        """Whether to process the frame with this stamp (and remember it if so)."""
        if self.max_rate <= 0:
            return True
        slot = int(stamp_ns) // max(1, round(1e9 / self.max_rate))
        if slot == self._last_slot:
            return False
        self._last_slot = slot
        return True
