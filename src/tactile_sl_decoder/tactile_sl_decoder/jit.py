"""Numba for the few per-glyph loops numpy cannot vectorise: compiled once, GIL released.

Kernels are compiled ahead of use for the argument types given with them (``signature``),
cached on disk beside their module (``make setup`` warms the cache, so a node starts without
compiling), and release the GIL: the pipeline's two image workers run them in parallel.
They are pure functions of arrays; the stage module that calls one keeps the numpy
reference it replaces in its tests, bit for bit.
"""
from __future__ import annotations

import concurrent.futures
import importlib
import multiprocessing
import os
import sys
import time
from typing import Any, Callable

import numba
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

_KERNELS: list[Any] = []

KERNEL_MODULES = ("tactile_sl_decoder.neighbours", "tactile_sl_decoder.extract.spacing",
                  "tactile_sl_decoder.extract.patches", "tactile_sl_decoder.extract.centroid",
                  "tactile_sl_decoder.classify.classifier",
                  "tactile_sl_decoder.classify.carry",
                  "tactile_sl_decoder.decode.links", "tactile_sl_decoder.decode.votes",
                  "tactile_sl_decoder.stereo.stereo", "tactile_sl_decoder.stereo.outliers",
                  "tactile_sl_decoder.touch.support",
                  "tactile_sl_decoder.touch.contact")
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


def _fma32(typingctx: Any, a: Any, b: Any, c: Any) -> Any:
    """A * b + c in float32 with one rounding (LLVM's ``llvm.fma.f32``), inside kernels.

    For kernels that must give the bits of library code using fused multiply-adds (OpenCV's
    SIMD interpolation): without ``fastmath`` numba never fuses a product and a sum itself.
    IEEE 754-2008, sec. 5.4.1 (fusedMultiplyAdd).
    """
    sig = types.float32(types.float32, types.float32, types.float32)

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        fnty = ir.FunctionType(ir.FloatType(), [ir.FloatType()] * 3)
        return builder.call(cgutils.get_or_insert_function(builder.module, fnty,
                                                           "llvm.fma.f32"), args)
    return sig, codegen


fma32: Any = intrinsic(_fma32)
"""``fma32(a, b, c)`` in kernels: :func:`_fma32`."""


def compiled_kernels() -> list[Any]:
    """Every kernel defined so far (those of the modules imported)."""
    return list(_KERNELS)


_TOUCH = "tactile_sl_decoder.touch."
WARM_GROUPS = (tuple(m for m in KERNEL_MODULES if m.startswith(_TOUCH)),
               tuple(m for m in KERNEL_MODULES if not m.startswith(_TOUCH)))
""":data:`KERNEL_MODULES` in two groups, the touch stage's and the rest: neither imports the
other's kernels and they take about as long to compile (35 and 36 s on a 2-vCPU AMD EPYC
VM), so ``make setup`` compiles them side by side."""


def _warm_group(modules: tuple[str, ...]) -> None:
    for name in modules:
        importlib.import_module(name)


def warm(processes: int | None = None) -> float:
    """Compile every kernel into the on-disk cache (``make setup``); returns the seconds.

    The groups of :data:`WARM_GROUPS` compile in parallel processes where there are cores
    for them (numba compiles on one core).
    """
    start = time.perf_counter()
    workers = min(len(WARM_GROUPS), processes or os.cpu_count() or 1)
    if workers <= 1:
        for group in WARM_GROUPS:
            _warm_group(group)
    else:
        context = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
            list(pool.map(_warm_group, WARM_GROUPS))
    return time.perf_counter() - start


if __name__ == "__main__":
    print(f"[setup] numba kernels ready ({len(KERNEL_MODULES)} modules, {warm():.1f} s)",
          file=sys.stderr)
