"""Morano's fill order as steps: each step writes a block of cells and completes one window.

Order: the first window (m x n cells), then the first m rows grow to the right one
m x 1 column at a time, then the first n columns grow downwards one 1 x n row at a time,
then every remaining cell in raster order. Every step completes exactly one new window, so
each step is checked once against the windows placed before it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constraints import Constraints
from .base import Budget, WindowIndex, window_at

MAX_ENUMERATED = 4096
"""Blocks with more value combinations than this are sampled instead of enumerated."""


@dataclass(frozen=True)
class Step:
    """Cells written by the step (row-major (r, c) pairs) and the window it completes."""

    cells: tuple[tuple[int, int], ...]
    window: tuple[int, int]


def morano_steps(rows: int, cols: int, window: tuple[int, int]) -> list[Step]:
    """The full step list for a rows x cols array."""
    m, n = window
    steps = [Step(tuple((r, c) for r in range(m) for c in range(n)), (0, 0))]
    for c in range(n, cols):
        steps.append(Step(tuple((r, c) for r in range(m)), (0, c - n + 1)))
    for r in range(m, rows):
        steps.append(Step(tuple((r, c) for c in range(n)), (r - m + 1, 0)))
    for r in range(m, rows):
        for c in range(n, cols):
            steps.append(Step(((r, c),), (r - m + 1, c - n + 1)))
    return steps


class StepFiller:
    """Applies steps to an array with a window index; shared by fill-and-test and pyramid."""

    def __init__(self, constraints: Constraints, rows: int, cols: int,
                 rng: np.random.Generator) -> None:
        self.c = constraints
        self.rows, self.cols = rows, cols
        self.array = np.zeros((rows, cols), dtype=np.uint8)
        self.index = WindowIndex(constraints, constraints.window_count(rows, cols))
        self.rng = rng
        self.steps = morano_steps(rows, cols, constraints.window)
        m, n = constraints.window
        self._local = {}
        for s in self.steps:
            r0, c0 = s.window
            self._local[s] = np.array([(r - r0) * n + (c - c0) for r, c in s.cells],
                                      dtype=np.intp)
        self.candidates_tried = 0

    def _candidates(self, size: int) -> np.ndarray:
        k = self.c.symbols
        total = k ** size
        if total <= MAX_ENUMERATED:
            order = self.rng.permutation(total)
        else:
            order = self.rng.integers(0, total, MAX_ENUMERATED)
        digits = (order[:, None] // (k ** np.arange(size - 1, -1, -1))[None, :]) % k
        return digits.astype(np.uint8)

    def try_step(self, step: Step) -> bool:
        """Write the first allowed random candidate for the step; False on a dead end."""
        r0, c0 = step.window
        base = window_at(self.array, r0, c0, self.c.window).copy()
        cand = self._candidates(len(step.cells))
        wins = np.repeat(base[None, :], len(cand), axis=0)
        wins[:, self._local[step]] = cand
        ok = self.index.allowed(wins)
        self.candidates_tried += len(cand)
        hits = np.flatnonzero(ok)
        if not len(hits):
            return False
        choice = cand[hits[0]]
        for (r, c), v in zip(step.cells, choice):
            self.array[r, c] = v
        self.index.add(wins[hits[0]])
        return True

    def undo_step(self, step: Step) -> None:
        """Remove the step's window from the index (cells are overwritten later)."""
        r0, c0 = step.window
        self.index.remove(window_at(self.array, r0, c0, self.c.window))

    def reset(self) -> None:
        """Start the whole pattern over."""
        self.array[:] = 0
        self.index.clear()


def check_size(constraints: Constraints, rows: int, cols: int) -> None:
    """Reject sizes smaller than one window."""
    m, n = constraints.window
    if rows < m or cols < n:
        raise ValueError(f"size {rows}x{cols} is smaller than the {m}x{n} window")


def progress_line(budget: Budget, placed: int, total: int, restarts: int, best: int) -> None:
    """Common progress display: windows placed now, best so far, restarts."""
    budget.report(f"windows {placed}/{total} (best {best}) restarts {restarts}")


def rows_complete(done: int, rows: int, cols: int, window: tuple[int, int]) -> int:
    """How many leading full-width rows the first ``done`` Morano steps have filled."""
    m, n = window
    strip = 1 + (cols - n)
    first_cols = strip + (rows - m)
    if done < strip:
        return 0
    if done < first_cols or cols == n:
        return min(rows, m + (done - strip) if cols == n else m)
    return min(rows, m + (done - first_cols) // (cols - n))
