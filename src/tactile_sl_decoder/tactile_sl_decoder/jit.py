"""Numba for the few per-glyph loops numpy cannot vectorise: compiled once, GIL released.

Kernels are compiled ahead of use for the argument types given with them (``signature``),
cached on disk beside their module (``make setup`` warms the cache, so a node starts without
compiling), and release the GIL: the pipeline's two image workers run them in parallel.
They are pure functions of arrays; the stage module that calls one keeps the numpy
reference it replaces in its tests, bit for bit.
"""
from __future__ import annotations

import importlib
import sys
import time
from typing import Any, Callable

import numba
import numpy as np

_KERNELS: list[Any] = []

KERNEL_MODULES = ("tactile_sl_decoder.decode.knn", "tactile_sl_decoder.extract.spacing")
"""The modules that define kernels: importing them compiles (or loads) every kernel."""


def kernel(signature: str | list[str]) -> Callable[[Callable[..., Any]], Any]:
    """``numba.njit`` with this project's settings: eager ``signature``, cache, nogil.

    No ``fastmath``: the kernels must give the same bits as the numpy code they replace.
    """
    def wrap(fn: Callable[..., Any]) -> Any:
        compiled = numba.njit(signature, cache=True, nogil=True, error_model="numpy")(fn)
        _KERNELS.append(compiled)
        return compiled
    return wrap


def helper(fn: Callable[..., Any]) -> Any:
    """A function only kernels call: compiled into each caller (typed by the call)."""
    return numba.njit(cache=True, nogil=True, error_model="numpy")(fn)


@helper
def point_buckets(x: np.ndarray, y: np.ndarray, cell: float) -> tuple[Any, ...]:
    """Counting sort of the points into square buckets of side ``cell``.

    Returns (bucket of each point, start, order, rows, cols): bucket b (row-major) holds
    the points ``order[start[b]:start[b + 1]]``.
    """
    n = x.shape[0]
    x0, y0 = x.min(), y.min()
    cols = int((x.max() - x0) / cell) + 1
    rows = int((y.max() - y0) / cell) + 1
    bucket = np.empty(n, np.int64)
    start = np.zeros(rows * cols + 1, np.int64)
    for i in range(n):
        b = int((y[i] - y0) / cell) * cols + int((x[i] - x0) / cell)
        bucket[i] = b
        start[b + 1] += 1
    for b in range(rows * cols):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[bucket[i]]] = i
        fill[bucket[i]] += 1
    return bucket, start, order, rows, cols


def compiled_kernels() -> list[Any]:
    """Every kernel defined so far (those of the modules imported)."""
    return list(_KERNELS)


def warm() -> float:
    """Compile every kernel into the on-disk cache (``make setup``); returns the seconds."""
    start = time.perf_counter()
    for name in KERNEL_MODULES:
        importlib.import_module(name)
    return time.perf_counter() - start


if __name__ == "__main__":
    print(f"[setup] numba kernels ready ({len(KERNEL_MODULES)} modules, {warm():.1f} s)",
          file=sys.stderr)
