"""Shared machinery for generators: results, failures, time budget, progress, window index."""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from itertools import combinations
from math import comb
from typing import Any, TextIO

import numpy as np

from ..constraints import Constraints
from ..verify import distances_to, pack_onehot

DENSE_LIMIT = 1 << 26
"""Largest code space k^(m*n) indexed by a dense counter array (64 MiB of int8)."""


class GenerationFailed(RuntimeError):
    """The generator ended (budget or exhausted search) without a complete pattern."""

    def __init__(self, reason: str, stats: dict[str, Any] | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.stats = stats or {}


@dataclass
class GenerationResult:
    """A complete array plus what it cost to find it."""

    array: np.ndarray
    algorithm: str
    seed: int
    seconds: float
    stats: dict[str, Any] = field(default_factory=dict)


class Budget:
    """Wall-clock budget plus a throttled one-line progress display on stderr."""

    def __init__(self, seconds: float | None, progress: bool | TextIO = False,
                 label: str = "") -> None:
        self.start = time.monotonic()
        self.deadline = None if seconds is None else self.start + float(seconds)
        self.stream: TextIO | None = (sys.stderr if progress is True else
                                      (progress if progress else None))
        self.label = label
        self._next_report = self.start + 0.5
        self._ticks = 0

    def elapsed(self) -> float:
        """Seconds since the budget started."""
        return time.monotonic() - self.start

    def expired(self) -> bool:
        """True once the time limit has passed (checked cheaply: every 256th call)."""
        self._ticks += 1
        if self.deadline is None or self._ticks & 0xFF:
            return False
        return time.monotonic() > self.deadline

    def expired_now(self) -> bool:
        """Exact check, for coarse-grained loops."""
        return self.deadline is not None and time.monotonic() > self.deadline

    def report(self, message: str, force: bool = False) -> None:
        """Show progress (at most twice a second unless forced)."""
        if self.stream is None:
            return
        now = time.monotonic()
        if not force and now < self._next_report:
            return
        self._next_report = now + 0.5
        self.stream.write(f"\r[{self.label} {now - self.start:7.1f}s] {message}\x1b[K")
        if force:
            self.stream.write("\n")
        self.stream.flush()

    def done(self) -> None:
        """End the progress line."""
        if self.stream is not None:
            self.stream.write("\n")
            self.stream.flush()


class WindowIndex:
    """The set of placed windows, answering "may this window be added?" incrementally.

    Two windows conflict when they are closer than ``min_hamming``. Dense mode (small code
    spaces): every placed window marks the Hamming ball of radius b = (h-1)//2 around it in
    a counter array, and a candidate probes its ball of radius a = h-1-b; two balls meet
    exactly when the distance is <= a + b = h-1. Otherwise (large windows) the candidate is
    compared with every placed window by bit-packed popcount. Both support removal, which
    backtracking and region restarts need.
    """

    def __init__(self, constraints: Constraints, capacity: int) -> None:
        self.c = constraints
        k, cells, h = constraints.symbols, constraints.cells, constraints.min_hamming
        self.k = k
        self.cells = cells
        self.powers = (k ** np.arange(cells - 1, -1, -1, dtype=np.int64))
        self.insert_r = (h - 1) // 2
        self.probe_r = h - 1 - self.insert_r
        ball = sum(_ball_terms(cells, k, r) for r in range(self.probe_r + 1))
        self.dense = k ** cells <= DENSE_LIMIT and self.probe_r <= 2 and ball <= 4096
        if self.dense:
            self.counts = np.zeros(k ** cells, dtype=np.int8)
            self._vals = np.arange(k, dtype=np.int64)
            self._pairs = np.array(list(combinations(range(cells), 2)), dtype=np.intp)
        else:
            self.packed = np.zeros((max(capacity, 1), _words(cells, k)), dtype=np.uint64)
            self.slot: dict[bytes, list[int]] = {}
            self.size = 0
            self.free: list[int] = []
        self.placed = 0

    # -- dense mode helpers -------------------------------------------------------------
    def _ball(self, digits: np.ndarray, radius: int) -> np.ndarray:
        """Codes within ``radius`` of each row of ``digits`` (B, cells) -> (B, ball)."""
        codes = digits.astype(np.int64) @ self.powers
        parts = [codes[:, None]]
        if radius >= 1:
            offs = (self._vals[None, None, :] - digits[:, :, None]) * self.powers[None, :, None]
            parts.append(codes[:, None] + offs.reshape(len(codes), -1))
            if radius >= 2:
                a = offs[:, self._pairs[:, 0], :]
                b = offs[:, self._pairs[:, 1], :]
                two = a[:, :, :, None] + b[:, :, None, :]
                parts.append(codes[:, None] + two.reshape(len(codes), -1))
        return np.concatenate(parts, axis=1)

    # -- public API ----------------------------------------------------------------------
    def allowed(self, windows: np.ndarray) -> np.ndarray:
        """For candidate windows (B, cells): which may be added to the placed set."""
        windows = np.asarray(windows).reshape(-1, self.cells)
        if self.placed == 0:
            return np.ones(len(windows), dtype=bool)
        if self.dense:
            ball = self._ball(windows, self.probe_r)
            return ~self.counts[ball].any(axis=1)
        live = self.packed[:self.size]
        dist = distances_to(live, pack_onehot(windows, self.k))
        if self.free:
            dist[:, self.free] = self.cells + 1
        return dist.min(axis=1) >= self.c.min_hamming

    def add(self, window: np.ndarray) -> None:
        """Record a placed window (the caller has checked it is allowed)."""
        window = np.asarray(window).reshape(1, self.cells)
        self.placed += 1
        if self.dense:
            self.counts[self._ball(window, self.insert_r)[0]] += 1
            return
        key = window.astype(np.uint8).tobytes()
        idx = self.free.pop() if self.free else self.size
        if idx == self.size:
            if idx >= len(self.packed):
                self.packed = np.concatenate([self.packed, np.zeros_like(self.packed)])
            self.size += 1
        self.packed[idx] = pack_onehot(window, self.k)[0]
        self.slot.setdefault(key, []).append(idx)

    def remove(self, window: np.ndarray) -> None:
        """Forget a previously added window."""
        window = np.asarray(window).reshape(1, self.cells)
        self.placed -= 1
        if self.dense:
            self.counts[self._ball(window, self.insert_r)[0]] -= 1
            return
        key = window.astype(np.uint8).tobytes()
        idx = self.slot[key].pop()
        if not self.slot[key]:
            del self.slot[key]
        self.packed[idx] = 0
        self.free.append(idx)

    def clear(self) -> None:
        """Forget everything (whole-pattern restart)."""
        self.placed = 0
        if self.dense:
            self.counts[:] = 0
        else:
            self.packed[:] = 0
            self.slot.clear()
            self.size = 0
            self.free.clear()


def _ball_terms(cells: int, k: int, radius: int) -> int:
    return comb(cells, radius) * (k - 1) ** radius


def _words(cells: int, k: int) -> int:
    return -(-cells * k // 64)


def window_at(array: np.ndarray, r: int, c: int, window: tuple[int, int]) -> np.ndarray:
    """The window whose top-left cell is (r, c), flattened row-major."""
    m, n = window
    return array[r:r + m, c:c + n].reshape(-1)
