"""Depth-first search with backtracking and randomised restarts (our search generator).

Cells are assigned one at a time: first the top strip of m rows column by column (so each
new column closes one window as early as possible), then the remaining rows in raster
order. When a cell closes a window, only the values whose window the incremental
:class:`~.base.WindowIndex` accepts are candidates (all k are tested in one vectorised
probe); the candidates are tried in a seeded random order, and a cell with none left
backtracks to the previous cell instead of discarding the whole pattern. Each attempt has
a backtrack limit following the Luby sequence (times ``unit``); when it is used up the
search restarts from an empty array with a fresh random order, which avoids thrashing in
one hopeless subtree.
"""
from __future__ import annotations

import numpy as np

from ..constraints import Constraints
from .base import Budget, GenerationFailed, GenerationResult, WindowIndex
from .steps import check_size

NAME = "dfs"
DEFAULT_UNIT = 2000


def luby(i: int) -> int:
    """The i-th term (1-based) of the Luby restart sequence 1 1 2 1 1 2 4 ..."""
    k = 1
    while (1 << k) - 1 < i:
        k += 1
    while True:
        if i == (1 << k) - 1:
            return 1 << (k - 1)
        i -= (1 << (k - 1)) - 1
        k = 1
        while (1 << k) - 1 < i:
            k += 1


def cell_order(rows: int, cols: int, window: tuple[int, int]) -> list[tuple[int, int]]:
    """Assignment order: the top m-row strip column by column, then raster order."""
    m, _ = window
    order = [(r, c) for c in range(cols) for r in range(m)]
    order += [(r, c) for r in range(m, rows) for c in range(cols)]
    return order


def generate(  # noqa: C901 - one backtracking search, its state shared by every step
        constraints: Constraints, rows: int, cols: int, seed: int = 0,
        time_limit: float | None = 60.0, progress: bool = False,
        unit: int = DEFAULT_UNIT) -> GenerationResult:
    """Backtracking search with Luby restarts until the array is complete or time ends."""
    check_size(constraints, rows, cols)
    budget = Budget(time_limit, progress, NAME)
    m, n = constraints.window
    k = constraints.symbols
    order = cell_order(rows, cols, constraints.window)
    total_cells = len(order)
    # for each position: the top-left of the window it closes, or None
    closes: list[tuple[int, int] | None] = []
    for r, c in order:
        closes.append((r - m + 1, c - n + 1) if r >= m - 1 and c >= n - 1 else None)
    windows_total = constraints.window_count(rows, cols)
    array = np.zeros((rows, cols), dtype=np.uint8)
    index = WindowIndex(constraints, windows_total)
    values = np.arange(k, dtype=np.uint8)
    root = np.random.SeedSequence(seed)
    attempt = 0
    best_pos = 0
    total_backtracks = 0
    nodes = 0
    while True:
        attempt += 1
        rng = np.random.default_rng(root.spawn(1)[0])
        limit = luby(attempt) * unit
        array[:] = 0
        index.clear()
        cands: list[np.ndarray | None] = [None] * total_cells
        ptr = [0] * total_cells
        pos = 0
        backtracks = 0
        placed_windows = 0
        while 0 <= pos < total_cells:
            r, c = order[pos]
            win = closes[pos]
            cand = cands[pos]
            if cand is None:
                if win is None:
                    cand = rng.permutation(values)
                else:
                    r0, c0 = win
                    base = array[r0:r0 + m, c0:c0 + n].reshape(-1)
                    trial = np.repeat(base[None, :], k, axis=0)
                    trial[:, -1] = values
                    ok = index.allowed(trial)
                    cand = rng.permutation(values[ok])
                cands[pos] = cand
                ptr[pos] = 0
            if ptr[pos] < len(cand):
                array[r, c] = cand[ptr[pos]]
                ptr[pos] += 1
                if win is not None:
                    r0, c0 = win
                    index.add(array[r0:r0 + m, c0:c0 + n].reshape(-1))
                    placed_windows += 1
                pos += 1
                nodes += 1
                if pos > best_pos:
                    best_pos = pos
                if not nodes & 0x3FF:
                    if budget.expired_now():
                        break
                    budget.report(f"windows {placed_windows}/{windows_total} attempt {attempt} "
                                  f"backtracks {total_backtracks + backtracks}")
                continue
            # dead end: undo the previous cell's choice and try its next value
            cands[pos] = None
            pos -= 1
            backtracks += 1
            if pos >= 0 and (closed := closes[pos]) is not None:
                r0, c0 = closed
                index.remove(array[r0:r0 + m, c0:c0 + n].reshape(-1))
                placed_windows -= 1
            if backtracks > limit or budget.expired():
                break
            budget.report(f"windows {placed_windows}/{windows_total} attempt {attempt} "
                          f"backtracks {total_backtracks + backtracks}")
        total_backtracks += backtracks
        if pos >= total_cells:
            budget.done()
            return GenerationResult(array.copy(), NAME, seed, budget.elapsed(), {
                "attempts": attempt, "backtracks": total_backtracks, "nodes": nodes,
                "windows": windows_total, "best_rows": rows})
        best_rows = _rows_from_pos(best_pos, rows, cols, m)
        if pos < 0:
            budget.done()
            raise GenerationFailed(
                "search space exhausted: no array of this size meets the constraints",
                {"attempts": attempt, "backtracks": total_backtracks, "best_rows": best_rows})
        if budget.expired_now():
            budget.done()
            raise GenerationFailed(
                f"time limit reached after {attempt} attempts and {total_backtracks} "
                f"backtracks; deepest reached {best_rows} complete rows of {rows}",
                {"attempts": attempt, "backtracks": total_backtracks, "nodes": nodes,
                 "best_rows": best_rows, "windows": windows_total})


def _rows_from_pos(pos: int, rows: int, cols: int, m: int) -> int:
    """Complete rows after ``pos`` cells in :func:`cell_order`."""
    strip = m * cols
    if pos < strip:
        return 0
    return min(rows, m + (pos - strip) // cols)
