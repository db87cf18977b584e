"""Cholesky factorisation and solves that release the GIL (LAPACK dpotrf / dpotrs).

The touch reference is prepared in a worker thread while the node keeps decoding frames.
SciPy's ``cho_factor`` / ``cho_solve`` hold the GIL for the whole LAPACK call (its f2py
wrappers do not release it): preparing an 840-cell reference stalled the frame thread for up
to half a second at a time (measured: 495 ms at once, 800 ms in all).  These call the very
same routines of the very same library (SciPy's OpenBLAS, through the function pointers
``scipy.linalg.cython_lapack`` exports) via :mod:`ctypes`, which releases the GIL for a
foreign call, on the same memory layout SciPy passes them, so the results are bit for bit
SciPy's (test).  LAPACK: Anderson et al., LAPACK Users' Guide, 3rd ed., SIAM 1999, DPOTRF /
DPOTRS.
"""
from __future__ import annotations

import ctypes
from typing import Any

import numpy as np
from scipy.linalg import cython_lapack

_INT = ctypes.POINTER(ctypes.c_int)
_DBL = ctypes.POINTER(ctypes.c_double)
_CHAR = ctypes.c_char_p


def _lapack(name: str, *argtypes: Any) -> Any:
    """A ctypes function (GIL released while it runs) of a SciPy cython_lapack routine."""
    capsule = cython_lapack.__pyx_capi__[name]
    get_name = ctypes.pythonapi.PyCapsule_GetName
    get_name.restype, get_name.argtypes = ctypes.c_char_p, [ctypes.py_object]
    get_pointer = ctypes.pythonapi.PyCapsule_GetPointer
    get_pointer.restype = ctypes.c_void_p
    get_pointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
    address = get_pointer(capsule, get_name(capsule))
    return ctypes.CFUNCTYPE(None, *argtypes)(address)


_dpotrf = _lapack("dpotrf", _CHAR, _INT, _DBL, _INT, _INT)
_dpotrs = _lapack("dpotrs", _CHAR, _INT, _INT, _DBL, _INT, _DBL, _INT, _INT)


def _ptr(a: np.ndarray) -> Any:
    return a.ctypes.data_as(_DBL)


def cho_factor_upper(a: np.ndarray, overwrite_a: bool = False) -> np.ndarray:
    """Upper Cholesky factor U (A = U^T U) of a symmetric positive definite matrix.

    Equal to ``scipy.linalg.cho_factor(a, lower=False)[0]``: a Fortran-ordered copy whose
    strict lower triangle still holds A's values (only :func:`cho_solve_upper` reads it).
    ``overwrite_a``: factor ``a`` itself when it is a Fortran-ordered float64 array (no
    copy; a per-frame solve). Raises ``numpy.linalg.LinAlgError`` if A is not positive
    definite.
    """
    c = a if overwrite_a and isinstance(a, np.ndarray) and a.dtype == np.float64 and (
        a.flags.f_contiguous and a.flags.writeable) else np.array(
            a, dtype=np.float64, order="F", copy=True)
    if c.ndim != 2 or c.shape[0] != c.shape[1]:
        raise ValueError(f"a square matrix is needed, got shape {c.shape}")
    n = ctypes.c_int(c.shape[0])
    info = ctypes.c_int(0)
    _dpotrf(b"U", ctypes.byref(n), _ptr(c), ctypes.byref(n), ctypes.byref(info))
    if info.value > 0:
        raise np.linalg.LinAlgError(f"{info.value}-th leading minor not positive definite")
    if info.value < 0:
        raise ValueError(f"illegal value in argument {-info.value} of dpotrf")
    return c


def cho_solve_upper(c: np.ndarray, b: np.ndarray) -> np.ndarray:
    """X with A X = B, A's factor from :func:`cho_factor_upper`; X Fortran-ordered.

    Equal to ``scipy.linalg.cho_solve((c, False), b)``.
    """
    if not (c.flags.f_contiguous and c.dtype == np.float64):
        raise ValueError("c must come from cho_factor_upper")
    x = np.array(b, dtype=np.float64, order="F", copy=True)
    vector = x.ndim == 1
    if vector:
        x = x.reshape(-1, 1, order="F")
    if x.shape[0] != c.shape[0]:
        raise ValueError(f"b has {x.shape[0]} rows, the factor is {c.shape[0]} x {c.shape[0]}")
    n, nrhs, info = ctypes.c_int(c.shape[0]), ctypes.c_int(x.shape[1]), ctypes.c_int(0)
    _dpotrs(b"U", ctypes.byref(n), ctypes.byref(nrhs), _ptr(c), ctypes.byref(n), _ptr(x),
            ctypes.byref(n), ctypes.byref(info))
    if info.value != 0:
        raise ValueError(f"illegal value in argument {-info.value} of dpotrs")
    return x[:, 0] if vector else x
