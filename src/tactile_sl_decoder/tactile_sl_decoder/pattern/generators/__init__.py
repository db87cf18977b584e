"""Pattern generators, by name: Morano's two and ours.

Each module exposes ``generate(constraints, rows, cols, seed, time_limit, progress)``
returning a :class:`GenerationResult` or raising :class:`GenerationFailed`.
"""
from __future__ import annotations

from typing import Callable

from ..bounds import code_bounds
from ..constraints import Constraints
from . import dfs, fill_and_test, linear, pyramid
from .base import Budget, GenerationFailed, GenerationResult

Generator = Callable[..., GenerationResult]

AUTO = "auto"


def generate_auto(constraints: Constraints, rows: int, cols: int, seed: int = 0,
                  time_limit: float | None = 60.0, progress: bool = False,
                  tidy: bool = False) -> GenerationResult:
    """Our best: the algebraic construction when GF(k) exists, else backtracking search.

    The linear construction is tried first with up to a quarter of the budget (it either
    finds a fold quickly or not at all); the search gets the rest.
    """
    budget = Budget(time_limit)
    reasons = []
    if linear.prime_power(constraints.symbols) is not None:
        share = None if time_limit is None else max(time_limit * 0.25, min(time_limit, 2.0))
        try:
            result = linear.generate(constraints, rows, cols, seed, share, progress, tidy)
            result.stats["via"] = linear.NAME
            result.algorithm = AUTO
            return result
        except GenerationFailed as exc:
            reasons.append(f"linear: {exc.reason}")
    remaining = None if time_limit is None else max(time_limit - budget.elapsed(), 0.1)
    try:
        result = dfs.generate(constraints, rows, cols, seed, remaining, progress)
    except GenerationFailed as exc:
        reasons.append(f"dfs: {exc.reason}")
        raise GenerationFailed("; ".join(reasons), exc.stats) from None
    result.stats["via"] = dfs.NAME
    result.algorithm = AUTO
    return result


GENERATORS: dict[str, Generator] = {
    AUTO: generate_auto,
    linear.NAME: linear.generate,
    dfs.NAME: dfs.generate,
    pyramid.NAME: pyramid.generate,
    fill_and_test.NAME: fill_and_test.generate,
}
"""Every generator by its ``--algorithm`` name; the first is the default."""

DESCRIPTIONS: dict[str, str] = {
    AUTO: "ours, default: linear when k is a prime power and a fold fits, else dfs",
    linear.NAME: "ours: m-sequence over GF(k) folded into the array (windows form a "
                 "linear code); reaches 728 windows (30x28) for k=3 3x3 h=3",
    dfs.NAME: "ours: depth-first search with backtracking, incremental window index, "
              "Luby restarts",
    pyramid.NAME: "Morano's hierarchical variant: regions with retry budgets 2^9, 2^8, ...",
    fill_and_test.NAME: "Morano's fill-and-test-as-you-go-along, whole restart on dead end",
}

__all__ = ["DESCRIPTIONS", "GENERATORS", "GenerationFailed", "GenerationResult", "generate"]


TIDY_ALGORITHMS = (AUTO, linear.NAME)
"""Generators that accept ``tidy`` (see :func:`linear.generate`)."""


def generate(name: str, constraints: Constraints, rows: int, cols: int, seed: int = 0,
             time_limit: float | None = 60.0, progress: bool = False,
             tidy: bool = False) -> GenerationResult:
    """Run the named generator (``tidy`` only for those in :data:`TIDY_ALGORITHMS`)."""
    try:
        func = GENERATORS[name]
    except KeyError:
        raise ValueError(f"unknown algorithm {name!r}; choose from {', '.join(GENERATORS)}") \
            from None
    windows = constraints.window_count(rows, cols)
    upper = code_bounds(constraints).upper
    if windows > upper:
        raise GenerationFailed(
            f"impossible: a {rows}x{cols} array has {windows} windows but no code with "
            f"{constraints.describe()} has more than {upper} words "
            "(see `tactile-sl pattern bound`)")
    options = {}
    if tidy:
        if name not in TIDY_ALGORITHMS:
            raise ValueError(f"tidy applies to {' and '.join(TIDY_ALGORITHMS)}, not {name}")
        options["tidy"] = True
    return func(constraints, rows, cols, seed=seed, time_limit=time_limit, progress=progress,
                **options)
