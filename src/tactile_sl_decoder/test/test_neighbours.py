"""Bucket-grid neighbour searches (neighbours.py) equal scipy's k-d tree queries, bit for bit."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from tactile_sl_decoder.neighbours import knn_within, nearest_within


def _tree(x, y, k, radius):
    pts = np.column_stack([x, y])
    return cKDTree(pts).query(pts, k=k, distance_upper_bound=radius)


def _lattice(rows, cols, spacing, jitter, seed, drop=0.0):
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.arange(cols) * spacing, np.arange(rows) * spacing),
                 -1).reshape(-1, 2) + rng.normal(0, jitter, (rows * cols, 2)) + 3.7
    g = g[rng.random(len(g)) >= drop]
    return np.ascontiguousarray(g[:, 0]), np.ascontiguousarray(g[:, 1])


@pytest.mark.parametrize("seed,drop,k", [(0, 0.0, 11), (1, 0.3, 11), (2, 0.0, 2),
                                         (3, 0.8, 5)])
def test_equals_the_kd_tree(seed, drop, k):
    x, y = _lattice(27, 28, 17.5, 1.5, seed, drop)
    radius = 3 * 17.5
    d0, i0 = _tree(x, y, k, radius)
    d1, i1 = knn_within(x, y, k, radius)
    assert np.array_equal(d0, d1) and np.array_equal(i0, i1)


def test_ties_are_ordered_by_index_and_missing_candidates_are_inf():
    x, y = _lattice(5, 5, 10.0, 0.0, 0)          # an exact lattice: many equal distances
    dist, idx = knn_within(x, y, 9, 10.5)
    centre = 12
    assert list(idx[centre, :5]) == [12, 7, 11, 13, 17]     # self, then 4 at 10, by index
    assert np.all(np.isinf(dist[centre, 5:])) and np.all(idx[centre, 5:] == 25)
    corner_d, corner_i = knn_within(x, y, 4, 10.5)
    assert list(corner_i[0]) == [0, 1, 5, 25] and np.isinf(corner_d[0, 3])


def test_few_or_no_points():
    d, i = knn_within(np.zeros(0), np.zeros(0), 3, 5.0)
    assert d.shape == (0, 3) and i.shape == (0, 3)
    d, i = knn_within(np.array([1.0, 2.0]), np.array([1.0, 1.0]), 4, 5.0)
    assert list(i[0]) == [0, 1, 2, 2] and d[0, 1] == 1.0 and np.isinf(d[0, 2])


@pytest.mark.parametrize("seed,radius", [(0, 5.0), (1, 0.3 * 17.5), (2, 40.0)])
def test_nearest_within_equals_the_kd_tree(seed, radius):
    x, y = _lattice(27, 28, 17.5, 1.0, seed, 0.1)
    rng = np.random.default_rng(seed + 10)
    qx = x + rng.normal(0, 3.0, len(x)) - 20.0 * (rng.random(len(x)) < 0.05)
    qy = y + rng.normal(0, 3.0, len(y))
    d0, i0 = cKDTree(np.column_stack([x, y])).query(np.column_stack([qx, qy]),
                                                     distance_upper_bound=radius)
    d1, i1 = nearest_within(qx, qy, x, y, radius)
    assert np.array_equal(d0, d1) and np.array_equal(i0, i1)
    d, i = nearest_within(qx, qy, np.zeros(0), np.zeros(0), radius)
    assert np.all(np.isinf(d)) and np.all(i == 0)
