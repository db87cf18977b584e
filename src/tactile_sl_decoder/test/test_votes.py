"""Window votes in numba (decode/votes.py) equal the numpy version they replaced."""
import numpy as np
import pytest

from tactile_sl_decoder.decode.votes import group_votes


def _reference(glyph, cell, ncells):
    """The numpy version (sort all votes), kept as the reference."""
    if len(glyph) == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z, z, z
    key = glyph.astype(np.int64) * ncells + cell
    uk, cnt = np.unique(key, return_counts=True)
    g, c = uk // ncells, uk % ncells
    order = np.lexsort((-cnt, g))
    g, c, cnt = g[order], c[order], cnt[order]
    first = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
    total = np.add.reduceat(cnt, first)
    second = np.zeros_like(total)
    has2 = np.r_[first[1:], len(g)] - first > 1
    second[has2] = cnt[first[has2] + 1]
    top = np.where(cnt[first] > second, cnt[first], 0)
    return g[first], c[first], top, total


@pytest.mark.parametrize("seed", range(8))
def test_equals_the_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 1500))
    m = int(rng.integers(0, 9 * n))
    glyph = rng.integers(0, n, m).astype(np.int64)
    cell = (rng.integers(0, int(rng.integers(1, 6)), m) + 7 * glyph).astype(np.int64)
    want = _reference(glyph, cell, 10**6)
    got = group_votes(glyph, cell)
    for a, b in zip(got, want):
        assert np.array_equal(a, b)


def test_ties_are_no_winner_and_the_lowest_cell_is_named():
    glyph = np.array([0, 0, 0, 0, 2, 2, 2], np.int64)
    cell = np.array([9, 5, 9, 5, 4, 4, 8], np.int64)
    g, c, top, total = group_votes(glyph, cell)
    assert list(g) == [0, 2] and list(c) == [5, 4]
    assert list(top) == [0, 2] and list(total) == [4, 3]
    assert all(len(a) == 0 for a in group_votes(np.zeros(0, np.int64), np.zeros(0, np.int64)))


@pytest.mark.parametrize("seed,p", [(0, 0.1), (1, 0.5), (2, 0.9)])
def test_linked_regions_equal_scipys_connected_components(seed, p):
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    from tactile_sl_decoder.decode.votes import linked_regions

    rng = np.random.default_rng(seed)
    n = 900
    nbr = rng.integers(-1, n, (n, 8)).astype(np.int64)
    ok = (rng.random((n, 8)) < p) & (nbr >= 0)
    indices = np.where(ok, nbr, np.arange(n)[:, None]).astype(np.int32)
    graph = csr_matrix((np.ones(8 * n), indices.reshape(-1),
                        np.arange(0, 8 * n + 1, 8, dtype=np.int32)), shape=(n, n))
    _, want = connected_components(graph, directed=False)
    got = linked_regions(nbr, ok)
    assert got.dtype == want.dtype and np.array_equal(got, want)
