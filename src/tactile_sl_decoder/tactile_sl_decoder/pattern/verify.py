"""Exact verification: minimum pairwise Hamming distance over all window pairs.

Windows are one-hot encoded and bit-packed into 64-bit words, so the symbol Hamming
distance of two windows is popcount(a XOR b) / 2; all pairs are then compared in blocks
with numpy (N^2/2 pairs: about 46 million for a 100x100 array with a 3x3 window, a couple
of seconds). The result is a certificate that states what was checked.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .constraints import Constraints

_BLOCK_BYTES = 1 << 25  # working-set size of one comparison block


def window_matrix(array: np.ndarray, window: tuple[int, int]) -> np.ndarray:
    """All windows of ``array`` as rows (row-major window order, row-major cells)."""
    m, n = window
    views = sliding_window_view(np.asarray(array), (m, n))
    return views.reshape(-1, m * n)


def pack_onehot(windows: np.ndarray, symbols: int) -> np.ndarray:
    """One-hot encode and bit-pack windows: (N, cells) -> (N, words) uint64."""
    count, cells = windows.shape
    onehot = np.zeros((count, cells, symbols), dtype=bool)
    np.put_along_axis(onehot, windows[:, :, None].astype(np.intp), True, axis=2)
    packed = np.packbits(onehot.reshape(count, cells * symbols), axis=1)
    pad = (-packed.shape[1]) % 8
    if pad:
        packed = np.pad(packed, ((0, 0), (0, pad)))
    return np.ascontiguousarray(packed).view(np.uint64)


def distances_to(packed: np.ndarray, probe: np.ndarray) -> np.ndarray:
    """Hamming distances from packed windows ``probe`` (P, words) to all of ``packed``."""
    xor = probe[:, None, :] ^ packed[None, :, :]
    return (np.bitwise_count(xor).sum(axis=2, dtype=np.int32) // 2)


@dataclass
class Certificate:
    """What the verifier found; ``valid`` means every claimed constraint holds."""

    constraints: Constraints
    rows: int
    cols: int
    windows: int
    min_distance: int | None
    histogram: dict[int, int]
    problems: list[str] = field(default_factory=list)
    closest_pair: tuple[tuple[int, int], tuple[int, int]] | None = None
    sha256: str = ""

    @property
    def valid(self) -> bool:
        """True when the pattern satisfies its constraints."""
        return not self.problems

    def text(self) -> str:
        """The printable certificate."""
        c = self.constraints
        lines = [
            "tactile-sl pattern certificate",
            f"constraints: {c.describe()}",
            f"array: {self.rows} x {self.cols} (sha256 of rows: {self.sha256})",
            f"windows: {self.windows} ({self.windows * (self.windows - 1) // 2} pairs "
            "compared exactly)",
            f"minimum Hamming distance: {self.min_distance}",
        ]
        if self.closest_pair is not None:
            (r0, c0), (r1, c1) = self.closest_pair
            lines.append(f"closest pair: windows at (row {r0}, col {c0}) and "
                         f"(row {r1}, col {c1})")
        lines.append("distance histogram (distance: pairs):")
        for dist in sorted(self.histogram):
            lines.append(f"  {dist}: {self.histogram[dist]}")
        if self.valid:
            lines.append(f"result: VALID (every two windows differ in >= {c.min_hamming} cells)")
        else:
            lines.append("result: INVALID")
            lines.extend(f"  problem: {p}" for p in self.problems)
        return "\n".join(lines) + "\n"


def array_sha256(array: np.ndarray) -> str:
    """Digest of the array as its YAML row strings (stable across dtypes)."""
    text = "\n".join("".join(str(int(v)) for v in row) for row in np.asarray(array))
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def pairwise_stats(windows: np.ndarray, symbols: int) -> tuple[int | None, dict[int, int],
                                                                tuple[int, int] | None]:
    """Exact minimum distance, histogram and one closest pair (window indices)."""
    count = len(windows)
    cells = windows.shape[1]
    if count < 2:
        return None, {}, None
    packed = pack_onehot(windows, symbols)
    words = packed.shape[1]
    block = max(1, min(count, _BLOCK_BYTES // (8 * words * count)))
    hist = np.zeros(cells + 1, dtype=np.int64)
    best = cells + 1
    best_pair: tuple[int, int] | None = None
    for start in range(0, count - 1, block):
        stop = min(start + block, count - 1)
        dist = distances_to(packed[start:], packed[start:stop])  # (B, count-start)
        # keep only pairs j > i: column index (relative to start) > row index
        upper = np.arange(count - start)[None, :] > np.arange(stop - start)[:, None]
        vals = dist[upper]
        hist += np.bincount(vals, minlength=cells + 1)
        masked = np.where(upper, dist, cells + 1)
        flat = int(np.argmin(masked))
        value = int(masked.flat[flat])
        if value < best:
            best = value
            i, j = divmod(flat, count - start)
            best_pair = (start + i, start + j)
    histogram = {d: int(n) for d, n in enumerate(hist) if n}
    return best, histogram, best_pair


def verify_array(array: np.ndarray, constraints: Constraints) -> Certificate:
    """Check shape, alphabet, uniqueness and minimum distance of an array."""
    problems: list[str] = []
    arr = np.asarray(array)
    if arr.ndim != 2:
        problems.append(f"array must be 2-D, got {arr.ndim}-D")
        return Certificate(constraints, 0, 0, 0, None, {}, problems)
    rows, cols = arr.shape
    m, n = constraints.window
    if rows < m or cols < n:
        problems.append(f"array {rows}x{cols} is smaller than the {m}x{n} window")
        return Certificate(constraints, rows, cols, 0, None, {}, problems)
    if arr.size and (arr.min() < 0 or arr.max() >= constraints.symbols):
        bad = np.argwhere((arr < 0) | (arr >= constraints.symbols))[0]
        problems.append(f"symbol {int(arr[tuple(bad)])} at (row {bad[0]}, col {bad[1]}) is "
                        f"outside 0..{constraints.symbols - 1}")
        return Certificate(constraints, rows, cols, 0, None, {}, problems)
    arr = arr.astype(np.uint8)
    windows = window_matrix(arr, constraints.window)
    best, histogram, pair = pairwise_stats(windows, constraints.symbols)
    wcols = cols - n + 1
    pair_rc = None
    if pair is not None:
        pair_rc = (divmod(pair[0], wcols), divmod(pair[1], wcols))
    if best is not None:
        if histogram.get(0):
            problems.append(f"{histogram[0]} pair(s) of identical windows (not unique)")
        if best < constraints.min_hamming:
            problems.append(f"minimum distance {best} < required {constraints.min_hamming}")
    return Certificate(constraints, rows, cols, len(windows), best, histogram, problems,
                       pair_rc, array_sha256(arr))


class PatternLike(Protocol):
    """What verification needs of a pattern (:class:`~.fileio.Pattern` is one)."""

    array: np.ndarray
    constraints: Constraints


def verify_pattern(pattern: PatternLike) -> Certificate:
    """Verify a loaded pattern against the constraints its file claims."""
    return verify_array(pattern.array, pattern.constraints)
