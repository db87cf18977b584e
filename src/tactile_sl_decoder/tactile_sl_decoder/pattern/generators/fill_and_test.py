"""Morano's fill-and-test-as-you-go-along generator.

The first window is random; the array then grows by random columns to the right, random
rows below and random single cells, each tested against every window placed so far. A
step for which no value works is a dead end, and the whole pattern starts over.
"""
from __future__ import annotations

import numpy as np

from ..constraints import Constraints
from .base import Budget, GenerationFailed, GenerationResult
from .steps import StepFiller, check_size, progress_line, rows_complete

NAME = "fill-and-test"


def generate(constraints: Constraints, rows: int, cols: int, seed: int = 0,
             time_limit: float | None = 60.0, progress: bool = False) -> GenerationResult:
    """Fill and test, restarting the whole pattern on any dead end, until the budget ends."""
    check_size(constraints, rows, cols)
    budget = Budget(time_limit, progress, NAME)
    rng = np.random.default_rng(seed)
    filler = StepFiller(constraints, rows, cols, rng)
    total = len(filler.steps)
    restarts = 0
    best = 0
    while True:
        filler.reset()
        done = 0
        for step in filler.steps:
            if not filler.try_step(step):
                break
            done += 1
            if budget.expired():
                break
            progress_line(budget, done, total, restarts, best)
        best = max(best, done)
        if done == total:
            budget.done()
            return GenerationResult(filler.array.copy(), NAME, seed, budget.elapsed(),
                                    {"restarts": restarts, "windows": total,
                                     "best_rows": rows})
        if budget.expired_now():
            budget.done()
            raise GenerationFailed(
                f"time limit reached after {restarts} restarts; best attempt placed "
                f"{best} of {total} windows",
                {"restarts": restarts, "best_windows": best, "windows": total,
                 "best_rows": rows_complete(best, rows, cols, constraints.window)})
        restarts += 1
