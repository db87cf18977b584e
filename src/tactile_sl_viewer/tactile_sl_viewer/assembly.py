"""The newest frame to show, put together by stamp, and the rates, latency and drops.

The ROS callbacks (or a bag reader) hand every message to :class:`FrameAssembler` as it
arrives: an O(1) store under a lock, nothing converted or encoded there, so a slow or absent
browser costs the callbacks nothing.  The page's side asks for :meth:`FrameAssembler.latest`
when it is ready for the next frame: the newest stamp whose decoder outputs are all in (or
that waited ``grace_s`` for the missing ones), every part of it from that one stereo frame.
Older frames are dropped for the page; only the last ``keep`` stamps are held.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

DECODER_PARTS = ("glyphs", "points", "field", "wrench", "contact", "depth", "slip")
"""What the decoder publishes per stereo frame (``glyphs``: left/symbols_decoded)."""
PARTS = ("image", *DECODER_PARTS)

WINDOW_S = 2.0          # rates and latency over the last two seconds
LIVE_S = 2.0            # a stream is live while it sent something this recently
DROP_AFTER_S = 1.0      # an image with no decoder output after this long was dropped
LIVE_STAMP_S = 60.0     # stamps further than this from the clock are not live (a bag's)


@dataclass
class FrameParts:
    """The messages of one stereo frame received so far, by part name."""

    stamp_ns: int
    parts: dict[str, Any] = field(default_factory=dict)
    first_output: float | None = None   # when its first decoder output arrived (monotonic)

    @property
    def key(self) -> tuple[int, tuple[str, ...]]:
        """Changes when the frame or its set of parts does (the page re-draws then)."""
        return self.stamp_ns, tuple(sorted(self.parts))


class FrameAssembler:
    """Messages in (any thread), the frame to show and the stream figures out (any thread)."""

    def __init__(self, keep: int = 8, grace_s: float = 0.1,
                 clock: Callable[[], float] = time.monotonic,
                 wall_ns: Callable[[], int] = time.time_ns) -> None:
        self.keep = int(keep)
        self.grace_s = float(grace_s)
        self._clock = clock
        self._wall_ns = wall_ns
        self._lock = threading.Lock()
        self._frames: dict[int, FrameParts] = {}
        self._last_arrival: dict[str, float] = {}
        self._arrivals: dict[str, deque[float]] = {p: deque(maxlen=256) for p in PARTS}
        self._decoded: deque[float] = deque(maxlen=256)
        self._latency: deque[tuple[float, float]] = deque(maxlen=256)
        self._pending_images: dict[int, float] = {}
        self._drops: deque[float] = deque(maxlen=4096)
        self.dropped_total = 0
        self.version = 0
        self._diagnostics: Any = None
        self._listeners: list[Callable[[], None]] = []

    def on_change(self, listener: Callable[[], None]) -> None:
        """Call ``listener()`` (from the adding thread) after every message."""
        self._listeners.append(listener)

    def add(self, part: str, msg: Any, stamp_ns: int) -> None:
        """Keep ``msg`` as ``part`` of the frame stamped ``stamp_ns``."""
        if part not in PARTS:
            raise ValueError(f"unknown frame part {part!r}")
        now = self._clock()
        with self._lock:
            newest = max(self._frames, default=None)
            if newest is not None and stamp_ns < newest - 1_000_000_000 \
                    and stamp_ns not in self._frames:
                self._frames.clear()                  # time went back: a bag started over
                self._pending_images.clear()
            frame = self._frames.get(stamp_ns)
            if frame is None:
                if len(self._frames) >= self.keep and stamp_ns < min(self._frames):
                    return                            # older than everything kept
                frame = self._frames[stamp_ns] = FrameParts(stamp_ns)
                while len(self._frames) > self.keep:
                    del self._frames[min(self._frames)]
            frame.parts[part] = msg
            self._last_arrival[part] = now
            self._arrivals[part].append(now)
            if part == "image":
                self._pending_images[stamp_ns] = now
            elif frame.first_output is None:
                frame.first_output = now
                self._decoded.append(now)
                self._latency.append((now, (self._wall_ns() - stamp_ns) / 1e6))
                self._pending_images.pop(stamp_ns, None)
            self._count_drops(now)
            self.version += 1
        for listener in self._listeners:
            listener()

    def reset(self) -> None:
        """Forget the frames held (a bag shows another one)."""
        with self._lock:
            self._frames.clear()
            self._pending_images.clear()
            self._last_arrival.clear()

    def add_diagnostics(self, msg: Any) -> None:
        """The newest DiagnosticArray (shown beside every frame)."""
        with self._lock:
            self._diagnostics = msg

    @property
    def diagnostics(self) -> Any:
        return self._diagnostics

    def _count_drops(self, now: float) -> None:
        """Images that got no decoder output within DROP_AFTER_S, while the decoder ran."""
        old = [s for s, t in self._pending_images.items() if now - t > DROP_AFTER_S]
        if not old:
            return
        alive = bool(self._decoded) and now - self._decoded[-1] < LIVE_S
        for stamp in old:
            del self._pending_images[stamp]
            if alive:
                self.dropped_total += 1
                self._drops.append(now)
        while len(self._pending_images) > 256:
            del self._pending_images[min(self._pending_images)]

    def latest(self) -> FrameParts | None:
        """The frame to show now (a copy), or None before anything arrived.

        While the decoder is live: the newest stamp with decoder outputs whose parts are
        complete (every part seen in the last seconds is there) or that waited ``grace_s``
        for the rest.  Without a decoder: the newest image.
        """
        now = self._clock()
        with self._lock:
            expected = {p for p, t in self._last_arrival.items() if now - t < LIVE_S}
            decoder_live = any(p in DECODER_PARTS for p in expected)
            for stamp in sorted(self._frames, reverse=True):
                frame = self._frames[stamp]
                if decoder_live:
                    if frame.first_output is None:
                        continue
                    if not expected <= frame.parts.keys() \
                            and now - frame.first_output < self.grace_s:
                        continue
                return FrameParts(frame.stamp_ns, dict(frame.parts), frame.first_output)
        return None

    def stats(self) -> dict[str, Any]:
        """Camera and decoded frame rates (Hz), latency (ms), drops; None where unknown."""
        now = self._clock()
        with self._lock:
            self._count_drops(now)
            lat = [ms for t, ms in self._latency if now - t < WINDOW_S]
            live_stamps = bool(lat) and abs(float(np.median(lat))) < LIVE_STAMP_S * 1e3
            return {
                "camera_hz": _rate(self._arrivals["image"], now),
                "decoded_hz": _rate(self._decoded, now),
                "latency_ms": float(np.median(lat)) if live_stamps else None,
                "latency_p90_ms": float(np.percentile(lat, 90)) if live_stamps else None,
                "dropped_10s": sum(1 for t in self._drops if now - t < 10.0),
                "dropped_total": self.dropped_total,
                "live": {p: now - t < LIVE_S for p, t in self._last_arrival.items()},
            }


def _rate(times: deque[float], now: float) -> float | None:
    """Events per second over the last WINDOW_S (None with fewer than two)."""
    recent = [t for t in times if now - t < WINDOW_S]
    if len(recent) < 2 or recent[-1] <= recent[0]:
        return None
    return (len(recent) - 1) / (recent[-1] - recent[0])
