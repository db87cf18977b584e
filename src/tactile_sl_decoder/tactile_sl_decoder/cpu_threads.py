"""Thread settings of the libraries the pipeline calls (OpenCV, BLAS, the GIL).

Per frame the work is a few milliseconds in many library calls; on a small shared machine
intra-op threads of several libraries only wait on each other, so the pipeline pins each
library to the threads it asks for. These settings are process-wide.
"""
from __future__ import annotations

import contextlib
import ctypes
import sys
import threading
from typing import Any, Iterator

import cv2


def set_cpu_threads(n: int) -> None:
    """Intra-op threads of OpenCV and OpenBLAS for this process (0 = leave them).

    Per frame the work is small (a few ms): with several threads per library on a small,
    shared machine the threads wait on each other (classifier inference, then on torch,
    measured 500 ms instead of 6 ms with 2 threads on 2 busy cores), so the pipeline runs
    them single-threaded.
    """
    if n <= 0:
        return

    if cv2.getNumThreads() != n:
        cv2.setNumThreads(n)
    _set_blas_threads(n)


_SET_NAMES = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
              "openblas_set_num_threads64_", "openblas_set_num_threads")
_GET_NAMES = ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
              "openblas_get_num_threads64_", "openblas_get_num_threads")


def _openblas_copies() -> list[tuple[Any, Any]]:
    """(set, get) thread-count functions of every OpenBLAS copy loaded in this process."""
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            paths = {line.split()[-1] for line in fh if "openblas" in line.lower()}
        libs = {p for p in paths
                if p.startswith("/") and "openblas" in p.rsplit("/", 1)[-1].lower()}
    except OSError:
        libs = set()
    copies = []
    for path in sorted(libs):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        setter = next((getattr(lib, n) for n in _SET_NAMES if hasattr(lib, n)), None)
        getter = next((getattr(lib, n) for n in _GET_NAMES if hasattr(lib, n)), None)
        if setter is not None and getter is not None:
            getter.restype = ctypes.c_int
            copies.append((setter, getter))
    return copies


def _set_blas_threads(n: int) -> None:
    """Threads of every OpenBLAS copy loaded in this process (numpy's, scipy's, OpenCV's).

    numpy's matrix products (the classifier) otherwise start one BLAS thread per core: with
    the two images classified in two workers on two cores, those threads spin against each
    other (measured: extraction + classification 12 ms instead of 9 ms per stereo pair).
    Applied on every call (once per pipeline: a count remembered instead went stale when
    something else had set them since, and a pipeline then ran with other counts, other
    rounding, than it asked for); libraries that are not loaded are left alone.  Inside a
    :func:`single_blas_thread` block the copies stay on one thread and take ``n`` when
    it ends.
    """
    with _pinned_lock:
        if _pinned:
            _pinned[1] = [(setter, n) for setter, _ in _pinned[1]]
            return
        for setter, _ in _openblas_copies():
            setter(ctypes.c_int(n))


_pinned_lock = threading.Lock()
_pinned: list[Any] = []     # [depth, saved counts] while some thread is inside single_blas_thread


@contextlib.contextmanager
def single_blas_thread() -> Iterator[None]:
    """Run a block with every loaded OpenBLAS on one thread, then give back the old counts.

    OpenBLAS splits a product or a factorisation among its threads, and the rounding
    depends on the split: the touch inversion computed with 2 threads differs from the one
    computed with 1 (by ~1e-19 N in the forces). What is cached on disk by its inputs
    (:mod:`.touch.solver_cache`) must be a function of those inputs alone, whatever a
    process set before, so it is computed on one thread. The counts are process-wide:
    blocks in several threads nest, and the last one out restores them (or the count
    :func:`set_cpu_threads` asked for meanwhile).
    """
    with _pinned_lock:
        if not _pinned:
            copies = _openblas_copies()
            saved = [(setter, int(getter())) for setter, getter in copies]
            for setter, _ in saved:
                setter(ctypes.c_int(1))
            _pinned[:] = [0, saved]
        _pinned[0] += 1
    try:
        yield
    finally:
        with _pinned_lock:
            _pinned[0] -= 1
            if _pinned[0] == 0:
                for setter, count in _pinned[1]:
                    setter(ctypes.c_int(count))
                _pinned.clear()


def shorten_switch_interval(ms: float) -> None:
    """Lower Python's GIL switch interval (process-wide) to at most ``ms`` milliseconds.

    A worker returning from a GIL-free call (OpenCV, the k-d tree, a matrix product) waits
    for the GIL until the other worker, busy with small numpy operations, is forced to hand
    it over: by default after 5 ms.  With the two images in two workers that wait dominated
    (stereo pair 21 ms at 5 ms, 16 ms at 1 ms; 0.2 ms gains nothing more).
    """
    if ms > 0 and sys.getswitchinterval() > 1e-3 * ms:
        sys.setswitchinterval(1e-3 * ms)
