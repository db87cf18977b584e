"""Glyph spacing on a bucket grid (extract/spacing.py) equals the k-d tree pair search."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from tactile_sl_decoder.extract.spacing import estimate_spacing, nearest_two


def _reference(u, v, search_px):
    """The k-d tree version it replaces (first and second nearest distances)."""
    n = len(u)
    pts = np.column_stack((u, v)).astype(np.float64)
    tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)
    first = np.full(n, np.inf)
    second = np.full(n, np.inf)
    pairs = tree.query_pairs(float(search_px), output_type="ndarray")
    d = np.hypot(*(pts[pairs[:, 0]] - pts[pairs[:, 1]]).T)
    who = pairs.T.reshape(-1)
    dist = np.concatenate((d, d))
    np.minimum.at(first, who, dist)
    is_first = dist == first[who]
    np.minimum.at(second, who[~is_first], dist[~is_first])
    second = np.where(np.bincount(who[is_first], minlength=n) >= 2, first, second)
    lacking = np.flatnonzero(np.isinf(second))
    if len(lacking):
        kk = min(3, n)
        dd, _ = tree.query(pts[lacking], k=kk)
        first[lacking], second[lacking] = dd[:, 1], dd[:, kk - 1]
    return first, second


@pytest.mark.parametrize("seed,search,jitter,drop", [(0, 21.0, 1.0, 0.0), (1, 21.0, 2.0, 0.4),
                                                    (2, 9.0, 1.0, 0.0), (3, 40.0, 0.0, 0.2),
                                                    (4, 3.0, 1.0, 0.0)])
def test_nearest_two_equals_the_pair_search(seed, search, jitter, drop):
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.arange(28) * 17.0, np.arange(27) * 17.0), -1).reshape(-1, 2)
    g = (g + rng.normal(0, jitter, g.shape) + 5.0)[rng.random(len(g)) >= drop]
    u, v = g[:, 0].astype(np.float32), g[:, 1].astype(np.float32)
    want = _reference(u, v, search)
    got = nearest_two(u.astype(np.float64), v.astype(np.float64), search)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def test_exact_lattice_ties_and_tiny_sets():
    u, v = (a.reshape(-1).astype(np.float64) for a in np.meshgrid(np.arange(4.0) * 10,
                                                                   np.arange(3.0) * 10))
    first, second = nearest_two(u, v, 12.0)
    assert np.all(first == 10.0) and np.all(second == 10.0)     # a tie is the second too
    first, second = nearest_two(np.array([0.0, 3.0]), np.array([0.0, 4.0]), 1.0)
    assert list(first) == [5.0, 5.0] and list(second) == [5.0, 5.0]
    assert estimate_spacing(np.zeros(1), np.zeros(1))[0] == 0.0
