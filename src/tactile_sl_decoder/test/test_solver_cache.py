"""Reference inversions kept on disk: read back bit for bit, never a wrong or broken entry."""
import os
import warnings

import numpy as np
import pytest

from tactile_sl_common.elasticity import Elastomer
from tactile_sl_decoder.touch import solver_cache
from tactile_sl_decoder.touch.solver_cache import SolverCache
from tactile_sl_decoder.touch.traction import TractionParams, TractionSolver

PAD = Elastomer(3e5, 0.49, 0.0)
PITCH = 5e-4
SHAPE = (9, 11)
CELLS = np.setdiff1d(np.arange(SHAPE[0] * SHAPE[1]), [0, 7, 50])   # a few not decoded


def _field(cells: np.ndarray, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    rows, cols = np.divmod(cells, SHAPE[1])
    dent = -2e-5 * np.exp(-((rows - 4) ** 2 + (cols - 5) ** 2) / 6.0)
    disp = np.column_stack([1e-6 * rng.standard_normal(len(cells)) + 0.2 * dent,
                            1e-6 * rng.standard_normal(len(cells)), dent])
    valid = np.ones(len(cells), bool)
    valid[[4, 20]] = False
    return disp, valid


def _same(a: TractionSolver, b: TractionSolver) -> None:
    assert a.area_fraction == b.area_fraction and a.scale == b.scale
    assert a.moment_noise == b.moment_noise
    assert np.array_equal(a._wrench_rows, b._wrench_rows)
    for x, y in zip(a._map_rows, b._map_rows):
        assert x.dtype == y.dtype == np.float32 and np.array_equal(x, y)
    assert np.array_equal(a._g32, b._g32)
    # the constrained inversion of the contact area (support_pressure) comes back too
    assert a.has_support == b.has_support
    assert a.support_gain.tobytes() == b.support_gain.tobytes()
    assert a._support_inverse.tobytes() == b._support_inverse.tobytes()
    if a._support_rows is not None and b._support_rows is not None:
        assert a._support_rows.dtype == b._support_rows.dtype == np.float32
        assert a._support_rows.tobytes() == b._support_rows.tobytes()
    disp, valid = _field(a.cells)
    fa, wa = a.solve(disp, valid)
    fb, wb = b.solve(disp, valid)
    assert fa.tobytes() == fb.tobytes() and wa.tobytes() == wb.tobytes()
    pa = a.support_pressure(1e-6, 2.0, 5.0)
    pb = b.support_pressure(1e-6, 2.0, 5.0)
    assert (pa is None) == (pb is None) == (not a.has_support)
    if pa is not None and pb is not None:
        assert pa.tobytes() == pb.tobytes() and pa.max() > 0


def test_an_inversion_read_back_gives_the_same_bytes(tmp_path):
    cache = SolverCache(tmp_path)
    plain = TractionSolver(PAD, PITCH, SHAPE, CELLS)
    first = TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache)
    assert (cache.hits, cache.misses) == (0, 1) and len(list(tmp_path.glob("*.npz"))) == 1
    again = TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache)
    assert (cache.hits, cache.misses) == (1, 1)
    _same(plain, first)
    _same(plain, again)
    assert plain.has_support


def test_a_solver_without_the_support_inversion_reads_back_without_it(tmp_path):
    cache = SolverCache(tmp_path)
    params = TractionParams(support_weight=0.0)
    TractionSolver(PAD, PITCH, SHAPE, CELLS, params, cache=cache)
    again = TractionSolver(PAD, PITCH, SHAPE, CELLS, params, cache=cache)
    assert cache.hits == 1 and not again.has_support
    _same(TractionSolver(PAD, PITCH, SHAPE, CELLS, params), again)


@pytest.mark.parametrize("change", ["cells", "weights", "support", "pad", "mirrored",
                                    "pitch"])
def test_anything_the_inversion_depends_on_gives_another_entry(tmp_path, change):
    cache = SolverCache(tmp_path)
    TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache)
    args = dict(elastomer=PAD, pitch=PITCH, shape=SHAPE, cells=CELLS, params=None,
                mirrored=False)
    args.update({"cells": {"cells": CELLS[1:]},
                 "weights": {"params": TractionParams(map_weight=0.5)},
                 "support": {"params": TractionParams(support_weight=1e-3)},
                 "pad": {"elastomer": Elastomer(3e5, 0.45, 0.0)},
                 "mirrored": {"mirrored": True}, "pitch": {"pitch": 6e-4}}[change])
    other = TractionSolver(cache=cache, **args)
    assert (cache.hits, cache.misses) == (0, 2)
    _same(other, TractionSolver(**args))


def test_the_key_holds_the_code_that_builds_the_inversion(tmp_path, monkeypatch):
    cache = SolverCache(tmp_path)
    TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache)
    monkeypatch.setattr("tactile_sl_decoder.touch.traction._code_digest", lambda: "edited")
    TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache)
    assert (cache.hits, cache.misses) == (0, 2)


def test_a_broken_entry_is_computed_again_with_a_warning(tmp_path):
    cache = SolverCache(tmp_path)
    TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache)
    (entry,) = tmp_path.glob("*.npz")
    entry.write_bytes(entry.read_bytes()[:1000])        # cut short: a crash while copying
    with pytest.warns(UserWarning, match="unreadable"):
        solver = TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache)
    _same(solver, TractionSolver(PAD, PITCH, SHAPE, CELLS))
    with warnings.catch_warnings():                     # and it was written again, whole
        warnings.simplefilter("error")
        _same(TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache), solver)


def test_a_directory_that_cannot_be_written_only_warns(tmp_path):
    blocked = tmp_path / "file"
    blocked.write_text("not a directory")
    cache = SolverCache(blocked / "traction")
    with pytest.warns(UserWarning, match="cannot write"):
        solver = TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache)
    _same(solver, TractionSolver(PAD, PITCH, SHAPE, CELLS))
    assert blocked.read_text() == "not a directory"


def test_the_least_recently_used_entries_go(tmp_path):
    cache = SolverCache(tmp_path, max_entries=2)
    keep = TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache)
    (first,) = tmp_path.glob("*.npz")
    os.utime(first, (1, 1))
    TractionSolver(PAD, PITCH, SHAPE, CELLS[1:], cache=cache)
    # older than any use to come: a file's write and a later os.utime() can carry the same
    # coarse kernel timestamp, and the tie then goes by the entries' names (their keys)
    (second,) = set(tmp_path.glob("*.npz")) - {first}
    os.utime(second, (2, 2))
    TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache)        # used again: recent
    TractionSolver(PAD, PITCH, SHAPE, CELLS[2:], cache=cache)    # a third: the oldest goes
    names = {p.name for p in tmp_path.glob("*.npz")}
    assert len(names) == 2 and first.name in names
    assert not list(tmp_path.glob(".tmp-*"))
    _same(keep, TractionSolver(PAD, PITCH, SHAPE, CELLS, cache=cache))


def test_the_default_directory_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert solver_cache.default_directory() == tmp_path / "tactile_sl" / "traction"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert solver_cache.default_directory() == tmp_path / ".cache" / "tactile_sl" / "traction"


def test_an_inversion_is_the_same_bytes_whatever_blas_threads_the_process_set():
    """A cached entry stands for its key alone: OpenBLAS's thread split must not show in it."""
    from tactile_sl_decoder import cpu_threads

    shape = (22, 20)             # 3N = 1320: large enough for OpenBLAS to split the work
    cells = np.arange(shape[0] * shape[1])
    copies = cpu_threads._openblas_copies()
    before = [get() for _, get in copies]
    solvers = []
    try:
        for threads in (2, 1):
            for setter, _ in copies:
                setter(threads)
            solvers.append(TractionSolver(PAD, PITCH, shape, cells))
    finally:                     # the process's counts as they were, for the other tests
        for (setter, _), count in zip(copies, before):
            setter(count)
    _same(*solvers)


def test_single_blas_thread_nests_and_gives_the_counts_back():
    from tactile_sl_decoder import cpu_threads

    copies = cpu_threads._openblas_copies()
    assert copies, "numpy's and scipy's OpenBLAS are loaded in this process"
    before = [get() for _, get in copies]
    with cpu_threads.single_blas_thread():
        with cpu_threads.single_blas_thread():
            assert [get() for _, get in copies] == [1] * len(copies)
        assert [get() for _, get in copies] == [1] * len(copies)
    assert [get() for _, get in copies] == before


def test_a_count_asked_for_inside_a_pinned_block_holds_after_it():
    """A pipeline made while another thread prepares an inversion keeps its own count."""
    from tactile_sl_decoder import cpu_threads

    copies = cpu_threads._openblas_copies()
    before = [get() for _, get in copies]
    try:
        cpu_threads.set_cpu_threads(2)
        with cpu_threads.single_blas_thread():
            cpu_threads.set_cpu_threads(1)
            assert [get() for _, get in copies] == [1] * len(copies)
            cpu_threads.set_cpu_threads(2)
            assert [get() for _, get in copies] == [1] * len(copies)   # still pinned
        assert [get() for _, get in copies] == [2] * len(copies)      # what was asked for
        for setter, _ in copies:          # set behind its back: the next call applies again
            setter(1)
        cpu_threads.set_cpu_threads(2)
        assert [get() for _, get in copies] == [2] * len(copies)
    finally:
        for (setter, _), count in zip(copies, before):
            setter(count)
