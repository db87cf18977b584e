"""Stereo frame capture through OpenCV VideoCapture: two devices or one side-by-side device.

Both devices are ``grab()``-ed back to back before either frame is decoded (``retrieve()``),
which keeps the two exposures as close in time as the driver allows; the caller stamps the
pair once, so left and right share the exact same stamp. A device that fails (unplugged,
read error, end of a video file) is released, logged once, and reopened every
``reopen_interval`` seconds: capture resumes by itself, nothing crashes.

Devices are given as an index (``0``), a device path (``/dev/video2``) or any file or URL
OpenCV can open (the tests use video files).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import cv2
import numpy as np

ENCODINGS = ("mono8", "bgr8")


def parse_device(spec: str | int) -> str | int:
    """``"0"`` -> 0 (a camera index); anything else stays a path/URL string."""
    if isinstance(spec, int):
        return spec
    text = str(spec).strip()
    return int(text) if text.isdigit() else text


@dataclass
class CaptureConfig:
    """What to open and how to deliver frames."""

    left_device: str | int = 0
    right_device: str | int = 1  # "" with side_by_side: one device, split in halves
    side_by_side: bool = False
    width: int = 640  # per camera
    height: int = 480
    fps: float = 30.0
    encoding: str = "mono8"
    fourcc: str = ""  # e.g. MJPG to get full frame rate from USB cameras; "" = driver default
    reopen_interval: float = 1.0

    def validate(self) -> "CaptureConfig":
        if self.encoding not in ENCODINGS:
            raise ValueError(f"encoding must be one of {', '.join(ENCODINGS)}, "
                             f"not {self.encoding!r}")
        if self.width <= 0 or self.height <= 0 or self.fps <= 0:
            raise ValueError("width, height and fps must be positive")
        if not self.side_by_side and str(self.right_device).strip() == "":
            raise ValueError("right_device is empty: give a device, or set side_by_side")
        if self.fourcc and len(self.fourcc) != 4:
            raise ValueError(f"fourcc must have 4 characters, not {self.fourcc!r}")
        return self


@dataclass
class StereoGrab:
    """One captured pair (before stamping)."""

    left: np.ndarray
    right: np.ndarray
    monotonic: float


class _Device:
    """One VideoCapture with lost/reopen bookkeeping."""

    def __init__(self, name: str, spec: str | int, cfg: CaptureConfig, frame_width: int,
                 opener: Callable[[Any], Any], log: Callable[[str, str], None]) -> None:
        self.name, self.spec, self.cfg = name, parse_device(spec), cfg
        self.frame_width = frame_width
        self.opener, self.log = opener, log
        self.cap: Any = None
        self.next_try = 0.0
        self.lost_logged = False

    def open(self, now: float) -> bool:
        if self.cap is not None:
            return True
        if now < self.next_try:
            return False
        self.next_try = now + self.cfg.reopen_interval
        cap = self.opener(self.spec)
        if cap is None or not cap.isOpened():
            if cap is not None:
                cap.release()
            if not self.lost_logged:
                self.log("error", f"{self.name} device {self.spec!r} cannot be opened; "
                         f"retrying every {self.cfg.reopen_interval:g} s")
                self.lost_logged = True
            return False
        if self.cfg.fourcc:
            cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*self.cfg.fourcc))
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, self.frame_width)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, self.cfg.height)
        cap.set(cv2.CAP_PROP_FPS, self.cfg.fps)
        self.cap = cap
        self.log("info", f"{self.name} device {self.spec!r} opened"
                 + (" again" if self.lost_logged else ""))
        self.lost_logged = False
        return True

    def lose(self, why: str, now: float) -> None:
        if self.cap is not None:
            self.cap.release()
        self.cap = None
        self.next_try = now + self.cfg.reopen_interval
        if not self.lost_logged:
            self.log("error", f"{self.name} device {self.spec!r} lost ({why}); retrying every "
                     f"{self.cfg.reopen_interval:g} s")
            self.lost_logged = True

    def release(self) -> None:
        if self.cap is not None:
            self.cap.release()
            self.cap = None


class StereoCapture:
    """Grab synchronised stereo pairs; ``read()`` returns None while a device is down."""

    def __init__(self, cfg: CaptureConfig, opener: Callable[[Any], Any] = cv2.VideoCapture,
                 log: Callable[[str, str], None] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.cfg = cfg.validate()
        self.clock = clock
        self.log = log or (lambda level, text: None)
        if cfg.side_by_side:
            self.devices = [_Device("stereo", cfg.left_device, cfg, 2 * cfg.width, opener,
                                    self.log)]
        else:
            self.devices = [_Device("left", cfg.left_device, cfg, cfg.width, opener, self.log),
                            _Device("right", cfg.right_device, cfg, cfg.width, opener,
                                    self.log)]
        self._size_warned = False

    def open(self) -> bool:
        """Try to open every device now (read() also retries); True if all are open."""
        now = self.clock()
        return all([d.open(now) for d in self.devices])

    def _convert(self, frame: np.ndarray) -> np.ndarray:
        if frame.ndim == 2:
            gray = frame
            return gray if self.cfg.encoding == "mono8" else cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
        if frame.shape[2] == 4:
            frame = cv2.cvtColor(frame, cv2.COLOR_BGRA2BGR)
        if self.cfg.encoding == "mono8":
            return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        return np.ascontiguousarray(frame)

    def read(self) -> StereoGrab | None:
        """The next pair, or None if a device is (still) down; never raises for device faults."""
        now = self.clock()
        if not all([d.open(now) for d in self.devices]):
            return None
        for d in self.devices:  # grab all first: the exposures stay close together
            try:
                ok = d.cap.grab()
            except cv2.error as exc:
                ok = False
                self.log("warning", f"{d.name}: grab raised {exc}")
            if not ok:
                d.lose("grab failed: unplugged, driver error or end of file", now)
                return None
        frames = []
        for d in self.devices:
            try:
                ok, frame = d.cap.retrieve()
            except cv2.error:
                ok, frame = False, None
            if not ok or frame is None or frame.size == 0:
                d.lose("retrieve failed", now)
                return None
            frames.append(frame)
        if self.cfg.side_by_side:
            both = frames[0]
            half = both.shape[1] // 2
            frames = [both[:, :half], both[:, half:2 * half]]
        left, right = (self._convert(f) for f in frames)
        if left.shape[:2] != right.shape[:2]:
            self.log("warning", f"left {left.shape[1]}x{left.shape[0]} and right "
                     f"{right.shape[1]}x{right.shape[0]} frames differ in size; pair dropped")
            return None
        if not self._size_warned and left.shape[:2] != (self.cfg.height, self.cfg.width):
            self.log("warning", f"devices deliver {left.shape[1]}x{left.shape[0]}, not the "
                     f"requested {self.cfg.width}x{self.cfg.height}; publishing as delivered")
            self._size_warned = True
        return StereoGrab(left, right, now)

    def close(self) -> None:
        for d in self.devices:
            d.release()
