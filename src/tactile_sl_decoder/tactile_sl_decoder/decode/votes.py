"""Window votes per glyph and linked regions of decoded glyphs (the decoder's counting steps).

Per glyph, the cell with the most votes wins unless another cell has as many (a tie is no
winner).  Compiled with numba (GIL released): a counting sort by glyph and a count of the
few (at most one per window holding the glyph) distinct cells each, instead of sorting all
votes; the same winners, counts and order as the numpy version it replaced.  The regions
of glyphs linked by consistent lattice neighbours come from a union-find, numbered as scipy's
connected components numbered them (tests).
"""
from __future__ import annotations

import numpy as np

from tactile_sl_decoder.jit import helper, kernel


@helper
def _tally(votes: np.ndarray) -> tuple[int, int, int]:
    """(most voted cell, the lowest of equals; its votes; the runner-up's votes)."""
    best_cell, best, second = -1, 0, 0
    for i in range(votes.shape[0]):
        c = votes[i]
        seen = False
        for j in range(i):                   # counted already (a few votes per glyph)
            if votes[j] == c:
                seen = True
                break
        if seen:
            continue
        count = 0
        for j in range(i, votes.shape[0]):
            count += votes[j] == c
        if count > best or (count == best and c < best_cell):
            if best_cell >= 0:
                second = best
            best, best_cell = count, c
        elif count > second:
            second = count
    return best_cell, best, second


@kernel("Tuple((int64[::1], int64[::1], int64[::1], int64[::1]))(int64[::1], int64[::1])")
def group_votes(glyph: np.ndarray, cell: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per glyph with votes, ascending: (glyph, winning cell, winning count, total count).

    The winning cell is the most voted one (the lowest cell of those equally voted); its
    count is 0 when another cell has as many votes.
    """
    m = glyph.shape[0]
    if m == 0:
        z = np.zeros(0, np.int64)
        return z, z.copy(), z.copy(), z.copy()
    n = glyph.max() + 1
    start = np.zeros(n + 1, np.int64)
    for i in range(m):
        start[glyph[i] + 1] += 1
    for g in range(n):
        start[g + 1] += start[g]
    fill = start[:-1].copy()
    votes = np.empty(m, np.int64)
    for i in range(m):
        votes[fill[glyph[i]]] = cell[i]
        fill[glyph[i]] += 1
    voted = 0
    for g in range(n):
        voted += start[g + 1] > start[g]
    out_g = np.empty(voted, np.int64)
    out_c = np.empty(voted, np.int64)
    out_top = np.empty(voted, np.int64)
    out_total = np.empty(voted, np.int64)
    k = 0
    for g in range(n):
        a, b = start[g], start[g + 1]
        if b == a:
            continue
        best_cell, best, second = _tally(votes[a:b])
        out_g[k] = g
        out_c[k] = best_cell
        out_top[k] = best if best > second else 0
        out_total[k] = b - a
        k += 1
    return out_g, out_c, out_top, out_total


@helper
def _root(parent: np.ndarray, i: int) -> int:
    while parent[i] != i:
        parent[i] = parent[parent[i]]        # path halving
        i = parent[i]
    return i


@kernel("int32[::1](int64[:, ::1], boolean[:, ::1])")
def linked_regions(neighbours: np.ndarray, linked: np.ndarray) -> np.ndarray:
    """Connected regions of glyphs joined by the links ``linked[i, k]`` to ``neighbours[i, k]``.

    Links count both ways.  Regions are numbered in the order of their first glyph, as
    ``scipy.sparse.csgraph.connected_components(directed=False)`` numbers them (union-find
    with path halving instead of a sparse graph; tests).
    """
    n, k = neighbours.shape
    parent = np.arange(n)
    for i in range(n):
        for s in range(k):
            if linked[i, s] and neighbours[i, s] >= 0:
                a, b = _root(parent, i), _root(parent, neighbours[i, s])
                if a != b:
                    if a < b:
                        parent[b] = a
                    else:
                        parent[a] = b
    label = np.full(n, -1, np.int32)
    comp = np.empty(n, np.int32)
    count = 0
    for i in range(n):
        r = _root(parent, i)
        if label[r] < 0:
            label[r] = count
            count += 1
        comp[i] = label[r]
    return comp


@kernel("boolean[::1](int64[:, ::1], int64[::1], int64[::1], int64[::1], int64[::1], "
        "boolean[::1], int64, int64)")
def confirmed_cells(links: np.ndarray, cell: np.ndarray, label: np.ndarray,
                    values: np.ndarray, delta: np.ndarray, valid_ext: np.ndarray,
                    min_agree: int, size: int) -> np.ndarray:
    """Which glyphs' candidate cells this frame confirms (``CodewordDecoder.confirm``).

    ``links`` (N, 8): each glyph's lattice neighbours (N = none); ``cell`` (N,): candidate
    internal cells (-1 none); ``label``: the glyphs' labels (-2 = not confident enough);
    ``values``: the pattern value of every internal cell; ``delta`` (8,): the neighbours'
    internal cell offsets; ``valid_ext``: cells inside the pattern.  Confirmed: the label is
    the pattern's value there, at least ``min_agree`` neighbours with a candidate imply
    this cell and none implies another, and no other glyph claims the same cell.
    """
    n = cell.shape[0]
    claims = np.zeros(size, np.int64)
    for i in range(n):
        if cell[i] >= 0:
            claims[cell[i]] += 1
    ok = np.zeros(n, np.bool_)
    for i in range(n):
        here = cell[i]
        if here < 0 or values[here] != label[i] or claims[here] > 1:
            continue
        agree = 0
        disagree = 0
        for s in range(8):
            j = links[i, s]
            there = cell[j] if j < n else -1
            if there < 0:
                continue
            implied = there - delta[s]
            if not valid_ext[implied]:
                implied = -1
            if implied == here:
                agree += 1
            else:
                disagree += 1
        ok[i] = agree >= min_agree and disagree == 0
    return ok
