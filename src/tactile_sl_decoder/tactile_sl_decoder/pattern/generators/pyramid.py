"""The hierarchical ("pyramid") variant of fill-and-test.

Choices where the method's description is ambiguous (documented in docs/pattern.md):

* Level 0 (the base) is the first window, the first m rows and the first n columns,
  filled exactly as fill-and-test does; a dead end there restarts the whole pattern.
* The rest of the array (rows >= m, columns >= n) is split into horizontal bands of
  ``band`` rows (default: the window height m), filled top to bottom, each in raster
  order. Band i rests on band i-1 (its windows overlap it), which is its enclosing level.
* A dead end inside band i clears and refills only band i. Band i may do this
  ``2 ** max(9 - i, 0)`` times (2^9, 2^8, ... for successive bands); when the retries are
  spent the restart climbs: band i-1 is cleared and refilled (costing one of its retries)
  and band i gets a fresh budget. Climbing past band 0 restarts the base.
"""
from __future__ import annotations

import numpy as np

from ..constraints import Constraints
from .base import Budget, GenerationFailed, GenerationResult
from .steps import Step, StepFiller, check_size, progress_line, rows_complete

NAME = "pyramid"
FIRST_BUDGET_EXP = 9


def _regions(filler: StepFiller, band: int) -> tuple[list[Step], list[list[Step]]]:
    m, n = filler.c.window
    base = [s for s in filler.steps if len(s.cells) > 1 or s.cells[0][0] < m
            or s.cells[0][1] < n]
    base_set = set(base)
    interior = [s for s in filler.steps if s not in base_set]
    regions: list[list[Step]] = []
    for s in interior:
        r = s.cells[0][0]
        idx = (r - m) // band
        while len(regions) <= idx:
            regions.append([])
        regions[idx].append(s)
    return base, [reg for reg in regions if reg]


def generate(  # noqa: C901 - one search whose retry levels share the filler and counters
        constraints: Constraints, rows: int, cols: int, seed: int = 0,
        time_limit: float | None = 60.0, progress: bool = False,
        band: int | None = None) -> GenerationResult:
    """Fill region by region with per-region retry budgets that climb on exhaustion."""
    check_size(constraints, rows, cols)
    budget = Budget(time_limit, progress, NAME)
    rng = np.random.default_rng(seed)
    filler = StepFiller(constraints, rows, cols, rng)
    base, regions = _regions(filler, band or constraints.window[0])
    total = len(filler.steps)
    retries_allowed = [2 ** max(FIRST_BUDGET_EXP - i, 0) for i in range(len(regions))]
    base_restarts = region_restarts = climbs = 0
    best = 0

    def fill(steps: list[Step]) -> int:
        """Apply steps in order; returns how many succeeded (stops at a dead end)."""
        for i, step in enumerate(steps):
            if not filler.try_step(step):
                return i
        return len(steps)

    def undo(steps: list[Step]) -> None:
        for step in reversed(steps):
            filler.undo_step(step)

    while True:
        # level 0: the base
        filler.reset()
        if fill(base) < len(base):
            base_restarts += 1
            if budget.expired_now():
                break
            continue
        placed = len(base)
        best = max(best, placed)
        used = [0] * len(regions)
        level = 0
        while 0 <= level < len(regions):
            if budget.expired():
                break
            done = fill(regions[level])
            if done == len(regions[level]):
                placed += done
                best = max(best, placed)
                progress_line(budget, placed, total, base_restarts + region_restarts, best)
                level += 1
                continue
            best = max(best, placed + done)
            undo(regions[level][:done])
            region_restarts += 1
            used[level] += 1
            while level >= 0 and used[level] > retries_allowed[level]:
                # retries spent: climb to the enclosing level and refill it
                used[level] = 0
                level -= 1
                climbs += 1
                if level >= 0:
                    undo(regions[level])
                    placed -= len(regions[level])
                    used[level] += 1
        if level == len(regions):
            budget.done()
            return GenerationResult(filler.array.copy(), NAME, seed, budget.elapsed(), {
                "base_restarts": base_restarts, "region_restarts": region_restarts,
                "climbs": climbs, "regions": len(regions), "windows": total,
                "best_rows": rows})
        if budget.expired_now():
            break
        base_restarts += 1
    budget.done()
    raise GenerationFailed(
        f"time limit reached ({base_restarts} base restarts, {region_restarts} region "
        f"restarts, {climbs} climbs); best attempt placed {best} of {total} windows",
        {"base_restarts": base_restarts, "region_restarts": region_restarts, "climbs": climbs,
         "best_windows": best, "windows": total,
         "best_rows": rows_complete(best, rows, cols, constraints.window)})
