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


def _confirmed_reference(links, cell, label, values, delta, valid_ext, min_agree, size):
    """The numpy version confirmed_cells replaced (CodewordDecoder.confirm), verbatim."""
    has = cell >= 0
    ok = has & (values[np.maximum(cell, 0)] == label)
    cj = np.append(cell, -1)[links]
    implied = cj - delta
    implied = np.where(valid_ext[implied], implied, -1)
    known = cj >= 0
    agree = (known & (implied == cell[:, None])).sum(axis=1)
    disagree = (known & (implied != cell[:, None])).sum(axis=1)
    ok &= (agree >= min_agree) & (disagree == 0)
    claims = np.bincount(cell[has], minlength=size)
    ok &= ~(has & (claims[np.maximum(cell, 0)] > 1))
    return ok


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_confirmed_cells_kernel_equals_the_numpy_version(seed):
    """Carried cells confirmed as the numpy version did: lattices with wrong, duplicated,
    missing candidates and labels, two images (groups)."""
    from tactile_sl_decoder.decode.codewords import _Layout, _links
    from tactile_sl_decoder.decode.grid import build_grid
    from tactile_sl_decoder.decode.votes import confirmed_cells

    rng = np.random.default_rng(seed)
    lay = _Layout(30, 32, 2)
    values = rng.integers(0, 3, lay.size).astype(np.int64)
    values[~lay.valid] = -1
    rr, cc = np.mgrid[0:20, 0:22]
    u = 20.0 + 18.0 * cc.ravel() + rng.normal(0, 0.8, cc.size)
    v = 20.0 + 18.0 * rr.ravel() + rng.normal(0, 0.8, rr.size)
    keep = rng.random(len(u)) > 0.05
    grid = build_grid(u[keep], v[keep])
    n = len(grid.nbr)
    group = (np.arange(n) >= n // 2).astype(np.int64)
    cell = lay.encode(group, rr.ravel()[keep] + 3, cc.ravel()[keep] + 4)
    label = values[cell].copy()
    flip = rng.random(n) < 0.05
    label[flip] = (label[flip] + 1) % 3                  # misread
    label[rng.random(n) < 0.03] = -2                     # not confident
    cell[rng.random(n) < 0.05] = -1                      # nothing carried
    wrong = rng.random(n) < 0.03
    cell[wrong] = lay.encode(group[wrong], rng.integers(0, 30, wrong.sum()),
                             rng.integers(0, 32, wrong.sum()))
    cell[5] = cell[40] if cell[40] >= 0 else cell[5]     # one cell claimed twice
    links = np.ascontiguousarray(_links(grid.nbr), dtype=np.int64)
    args = (links, cell, label, values, lay.delta.astype(np.int64), lay.valid_ext, 2, lay.size)
    want = _confirmed_reference(*args)
    got = confirmed_cells(*args)
    assert np.array_equal(got, want) and 0.3 < want.mean() < 0.95
