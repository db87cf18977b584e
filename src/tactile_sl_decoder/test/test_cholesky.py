"""GIL-free Cholesky (touch/cholesky.py): bit for bit SciPy's, and no Python-API calls."""
import ctypes

import numpy as np
import pytest
import scipy.linalg

from tactile_sl_decoder.touch import cholesky, traction
from tactile_sl_decoder.touch.cholesky import cho_factor_upper, cho_solve_upper


def _spd(n, seed=0):
    g = np.random.default_rng(seed).random((n, n))
    return g, g.T @ g + 0.1 * np.eye(n)


def test_factor_and_solves_equal_scipy_bit_for_bit():
    g, h = _spd(300)
    want = scipy.linalg.cho_factor(h, lower=False, check_finite=False)
    got = cho_factor_upper(h)
    assert np.array_equal(got, want[0]) and got.flags.f_contiguous
    for b in (g.T, g[:6].T, g[0], np.ascontiguousarray(g[:, :7])):
        x = cho_solve_upper(got, b)
        ref = scipy.linalg.cho_solve(want, b, check_finite=False)
        assert np.array_equal(x, ref) and x.flags.f_contiguous == ref.flags.f_contiguous


def test_overwrite_factors_a_fortran_float64_array_in_place_and_copies_others():
    _, h = _spd(50, seed=1)
    want = cho_factor_upper(h)
    a = np.asfortranarray(h)
    got = cho_factor_upper(a, overwrite_a=True)
    assert got is a and np.array_equal(got, want)
    c_ordered = np.ascontiguousarray(h)          # not Fortran-ordered: copied, left as it was
    assert np.array_equal(cho_factor_upper(c_ordered, overwrite_a=True), want)
    assert np.array_equal(c_ordered, h)


def test_not_positive_definite_and_bad_shapes_are_clear_errors():
    with pytest.raises(np.linalg.LinAlgError, match="positive definite"):
        cho_factor_upper(-np.eye(4))
    with pytest.raises(ValueError, match="square"):
        cho_factor_upper(np.ones((3, 4)))
    with pytest.raises(ValueError, match="rows"):
        cho_solve_upper(cho_factor_upper(np.eye(4)), np.ones(5))


def test_lapack_calls_release_the_gil():
    """ctypes releases the GIL around a CFUNCTYPE call (not around a PYFUNCTYPE one)."""
    for fn in (cholesky._dpotrf, cholesky._dpotrs):
        assert isinstance(fn, ctypes._CFuncPtr)
        assert not fn._flags_ & ctypes._FUNCFLAG_PYTHONAPI


def test_the_traction_solver_never_uses_scipys_gil_holding_cholesky(monkeypatch):
    """SciPy's cho_factor / cho_solve hold the GIL: a reference prepared beside the frames
    stalled the node's frame thread for up to 0.5 s at a time (the `points` gap after a tare)."""
    def refuse(*_args, **_kwargs):
        raise AssertionError("scipy.linalg.cho_* holds the GIL for the whole call")
    monkeypatch.setattr(scipy.linalg, "cho_factor", refuse)
    monkeypatch.setattr(scipy.linalg, "cho_solve", refuse)
    from tactile_sl_common.elasticity import Elastomer

    solver = traction.TractionSolver(Elastomer(3e5, 0.49, 0.0), 5e-4, (6, 5), np.arange(30))
    assert solver.area_fraction > 0
