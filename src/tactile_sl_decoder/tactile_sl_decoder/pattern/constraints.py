"""Pattern constraints: alphabet size, window shape and minimum Hamming distance."""
from __future__ import annotations

import re
from dataclasses import dataclass

MIN_SYMBOLS = 2
MAX_SYMBOLS = 8
MIN_WINDOW = 3
MAX_WINDOW = 7


@dataclass(frozen=True)
class Constraints:
    """What every generated pattern must satisfy.

    ``symbols`` is the alphabet size k (values 0..k-1), ``window`` the codeword window
    (rows, cols) and ``min_hamming`` the minimum number of differing cells between any two
    windows (1 means plain uniqueness).
    """

    symbols: int
    window: tuple[int, int]
    min_hamming: int

    def __post_init__(self) -> None:
        """Reject constraints outside the supported range early, with the reason."""
        k, (m, n), h = self.symbols, self.window, self.min_hamming
        if not MIN_SYMBOLS <= k <= MAX_SYMBOLS:
            raise ValueError(f"symbols must be in {MIN_SYMBOLS}..{MAX_SYMBOLS}, got {k}")
        for side in (m, n):
            if not MIN_WINDOW <= side <= MAX_WINDOW:
                raise ValueError(
                    f"window sides must be in {MIN_WINDOW}..{MAX_WINDOW}, got {m}x{n}")
        if not 1 <= h <= m * n:
            raise ValueError(f"min_hamming must be in 1..{m * n} for a {m}x{n} window, got {h}")

    @property
    def cells(self) -> int:
        """Number of cells in one window (the code length)."""
        return self.window[0] * self.window[1]

    def window_count(self, rows: int, cols: int) -> int:
        """Number of windows in a rows x cols array (non-toroidal)."""
        m, n = self.window
        return max(rows - m + 1, 0) * max(cols - n + 1, 0)

    def describe(self) -> str:
        """Short human-readable form used in logs and certificates."""
        m, n = self.window
        return f"k={self.symbols}, window {m}x{n}, h={self.min_hamming}"


_SHAPE_RE = re.compile(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$")


def parse_shape(text: str) -> tuple[int, int]:
    """Parse ``"MxN"`` (rows x cols) as used by ``--window`` and ``--size``."""
    match = _SHAPE_RE.match(text)
    if not match:
        raise ValueError(f"expected ROWSxCOLS such as 3x3, got {text!r}")
    rows, cols = int(match.group(1)), int(match.group(2))
    if rows < 1 or cols < 1:
        raise ValueError(f"shape sides must be positive, got {text!r}")
    return rows, cols
