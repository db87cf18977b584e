"""Neighbour searches among glyph centres on a bucket grid (numba; no k-d tree to build).

Shared by the stages: the lattice's k nearest neighbours (:func:`knn_within`), the carried
labels' match to the previous frame (:func:`nearest_within`) and the spacing estimate
(:func:`point_buckets`).

Glyph centres are nearly a lattice and the lattice search only wants the neighbours within
three spacings: a square bucket grid of a third of that radius, searched in rings around a
point's bucket until no farther ring can hold a nearer point, finds them after looking at
about 25-50 candidates.  Per image (~750 glyphs) this costs a tenth of building and querying
a ``scipy.spatial.cKDTree`` and runs without the GIL.  Distances are computed as the k-d
tree computes them (sqrt of dx^2 + dy^2, summed in that order), neighbours sorted by
distance, then index: the results are the tree's, bit for bit (tests).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from tactile_sl_decoder.jit import helper, kernel


@helper
def point_buckets(x: np.ndarray, y: np.ndarray, cell: float) -> tuple[Any, ...]:
    """Counting sort of the points into square buckets of side ``cell``.

    Returns (bucket of each point, start, order, rows, cols): bucket b (row-major) holds
    the points ``order[start[b]:start[b + 1]]``.
    """
    n = x.shape[0]
    x0, y0 = x.min(), y.min()
    cols = int((x.max() - x0) / cell) + 1
    rows = int((y.max() - y0) / cell) + 1
    bucket = np.empty(n, np.int64)
    start = np.zeros(rows * cols + 1, np.int64)
    for i in range(n):
        b = int((y[i] - y0) / cell) * cols + int((x[i] - x0) / cell)
        bucket[i] = b
        start[b + 1] += 1
    for b in range(rows * cols):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[bucket[i]]] = i
        fill[bucket[i]] += 1
    return bucket, start, order, rows, cols


@helper
def _insert(best_d: np.ndarray, best_i: np.ndarray, found: int, d: float, j: int) -> int:
    """Insert candidate j at squared distance d into the sorted best list; new length."""
    k = best_d.shape[0]
    if found == k and (d > best_d[k - 1] or (d == best_d[k - 1] and j > best_i[k - 1])):
        return found
    at = found if found < k else k - 1
    while at > 0 and (best_d[at - 1] > d or (best_d[at - 1] == d and best_i[at - 1] > j)):
        best_d[at] = best_d[at - 1]
        best_i[at] = best_i[at - 1]
        at -= 1
    best_d[at] = d
    best_i[at] = j
    return found + 1 if found < k else found


@kernel("Tuple((float64[:, ::1], int64[:, ::1]))(float64[::1], float64[::1], int64, float64)")
def knn_within(x: np.ndarray, y: np.ndarray, k: int, radius: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest points of every point (itself first) closer than ``radius``.

    Returns distances (N, k) and indices (N, k), ascending by distance then index; missing
    candidates are ``inf`` and index N, as ``cKDTree.query(distance_upper_bound=radius)``.
    """
    n = x.shape[0]
    dist = np.full((n, k), np.inf)
    idx = np.full((n, k), n, np.int64)
    if n == 0 or k <= 0:
        return dist, idx
    # buckets of a third of the radius, searched ring by ring around the point's bucket
    # until no unseen bucket can hold a point nearer than the k-th found
    cell = radius / 3.0
    bucket, start, order, rows, cols = point_buckets(x, y, cell)
    rings = int(math.ceil(radius / cell)) + 1
    bound = radius * radius
    best_d = np.empty(k)
    best_i = np.empty(k, np.int64)
    for i in range(n):
        found = 0
        bi, bj = bucket[i] // cols, bucket[i] % cols
        for ring in range(rings + 1):
            reach = (ring - 1) * cell * (1.0 - 1e-9)   # no point of this ring is nearer
            if ring > 0 and found == k and reach * reach > best_d[k - 1]:
                break
            for r in range(max(bi - ring, 0), min(bi + ring + 1, rows)):
                step = 1 if r == bi - ring or r == bi + ring else max(2 * ring, 1)
                for c in range(bj - ring, bj + ring + 1, step):
                    if c < 0 or c >= cols:
                        continue
                    b = r * cols + c
                    for p in range(start[b], start[b + 1]):
                        j = order[p]
                        dx = x[i] - x[j]
                        dy = y[i] - y[j]
                        d = 0.0 + dx * dx              # the k-d tree's sum, in its order
                        d = d + dy * dy
                        if d < bound:
                            found = _insert(best_d, best_i, found, d, j)
        for m in range(found):
            dist[i, m] = math.sqrt(best_d[m])
            idx[i, m] = best_i[m]
    return dist, idx


@kernel("Tuple((float64[::1], int64[::1]))(float64[::1], float64[::1], float64[::1], "
        "float64[::1], float64)")
def nearest_within(qx: np.ndarray, qy: np.ndarray, px: np.ndarray, py: np.ndarray,
                   radius: float) -> tuple[np.ndarray, np.ndarray]:
    """For every query point, the nearest of the points (px, py) closer than ``radius``.

    Distance (sqrt of the squared sum) and index, ``inf`` and len(px) where none is that
    close; equal distances go to the lower index.  As ``cKDTree(p).query(q, k=1,
    distance_upper_bound=radius)``.
    """
    nq, npts = qx.shape[0], px.shape[0]
    dist = np.full(nq, np.inf)
    idx = np.full(nq, npts, np.int64)
    if nq == 0 or npts == 0:
        return dist, idx
    cell = radius
    bucket, start, order, rows, cols = point_buckets(px, py, cell)
    x0, y0 = px.min(), py.min()
    bound = radius * radius
    for i in range(nq):
        bi = int(math.floor((qy[i] - y0) / cell))
        bj = int(math.floor((qx[i] - x0) / cell))
        best = bound
        who = npts
        for r in range(max(bi - 1, 0), min(bi + 2, rows)):
            for c in range(max(bj - 1, 0), min(bj + 2, cols)):
                b = r * cols + c
                for p in range(start[b], start[b + 1]):
                    j = order[p]
                    dx = qx[i] - px[j]
                    dy = qy[i] - py[j]
                    d = 0.0 + dx * dx
                    d = d + dy * dy
                    if d < best or (d == best and j < who and d < bound):
                        best = d
                        who = j
        if who < npts:
            dist[i] = math.sqrt(best)
            idx[i] = who
    return dist, idx
