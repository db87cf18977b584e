"""Thread settings of the libraries the pipeline calls (OpenCV, BLAS, the GIL).

Per frame the work is a few milliseconds in many library calls; on a small shared machine
intra-op threads of several libraries only wait on each other, so the pipeline pins each
library to the threads it asks for. These settings are process-wide.
"""
from __future__ import annotations

import ctypes
import sys

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


_BLAS_THREADS: list[int] = []      # the thread count last given to the loaded OpenBLAS copies


def _set_blas_threads(n: int) -> None:
    """Threads of every OpenBLAS copy loaded in this process (numpy's, scipy's, OpenCV's).

    numpy's matrix products (the classifier) otherwise start one BLAS thread per core: with
    the two images classified in two workers on two cores, those threads spin against each
    other (measured: extraction + classification 12 ms instead of 9 ms per stereo pair).
    Done once per count; libraries that are not loaded are left alone.
    """
    if _BLAS_THREADS == [n]:
        return

    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            paths = {line.split()[-1] for line in fh if "openblas" in line.lower()}
        libs = {p for p in paths
                if p.startswith("/") and "openblas" in p.rsplit("/", 1)[-1].lower()}
    except OSError:
        libs = set()
    for path in sorted(libs):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
                     "openblas_set_num_threads64_", "openblas_set_num_threads"):
            fn = getattr(lib, name, None)
            if fn is not None:
                fn(ctypes.c_int(n))
                break
    _BLAS_THREADS[:] = [n]


def shorten_switch_interval(ms: float) -> None:
    """Lower Python's GIL switch interval (process-wide) to at most ``ms`` milliseconds.

    A worker returning from a GIL-free call (OpenCV, the k-d tree, a matrix product) waits
    for the GIL until the other worker, busy with small numpy operations, is forced to hand
    it over: by default after 5 ms.  With the two images in two workers that wait dominated
    (stereo pair 21 ms at 5 ms, 16 ms at 1 ms; 0.2 ms gains nothing more).
    """
    if ms > 0 and sys.getswitchinterval() > 1e-3 * ms:
        sys.setswitchinterval(1e-3 * ms)
