"""The lattice's neighbour table from local lattice vectors (step 4-5 of decode/grid.py).

Per glyph: each of its 8 neighbours is the candidate (one of its k nearest glyphs) closest
to the displacement the local lattice vectors predict, within ``match_tol`` local spacings;
then links must be mutual and diagonals agree with the two-step paths through the
4-neighbours.  Compiled with numba (GIL released, one pass per glyph instead of a few dozen
(N, K) numpy operations); the arithmetic is that of the numpy version it replaced, operation
for operation (float32 where it was float32), so the table is the same (tests).
"""
from __future__ import annotations

import numpy as np

from tactile_sl_decoder.jit import helper, kernel

# Neighbour slots 0..7 and their columns of the (N, 9) table (row-major 3x3, centre 4).
_SLOT_COLUMN = np.array([0, 1, 2, 3, 5, 6, 7, 8], np.int64)
_SLOT_DC = np.array([-1.0, 0.0, 1.0, -1.0, 1.0, -1.0, 0.0, 1.0])   # column step of a slot
_SLOT_DR = np.array([-1.0, -1.0, -1.0, 0.0, 0.0, 1.0, 1.0, 1.0])   # row step of a slot
_DIAGONALS = np.array([[0, 1, 3], [2, 1, 5], [6, 7, 3], [8, 7, 5]], np.int64)
"""(diagonal column, the column of its (dr, 0) neighbour, the column of its (0, dc) one)."""
_SORT5_A = np.array([0, 3, 2, 2, 0, 0, 1, 1, 1], np.int64)
_SORT5_B = np.array([1, 4, 4, 3, 3, 2, 4, 3, 2], np.int64)
"""An optimal sorting network for 5 values (9 compare-exchanges a, b)."""


@helper
def _mutual(nbr: np.ndarray) -> None:
    """Keep only mutual links: j = nbr[i, o] requires nbr[j, 8 - o] == i (in place)."""
    n = nbr.shape[0]
    before = nbr.copy()                     # every link judged on the table as it was
    for i in range(n):
        for o in range(9):
            if o == 4:
                continue
            j = before[i, o]
            if j >= 0 and before[j, 8 - o] != i:
                nbr[i, o] = -1


@helper
def _match_one(du32: np.ndarray, dv32: np.ndarray, valid: np.ndarray, pred_u: np.ndarray,
               pred_v: np.ndarray, tol2: float, c: np.ndarray, r: np.ndarray,
               match_tol: float, links: np.ndarray) -> None:
    """One glyph's 8 links (candidate index or -1) into ``links``.

    Fast path: a candidate's lattice coordinates, rounded, name the only prediction it can
    be within tolerance of; where the local vectors are too oblique or two candidates hit
    one prediction, every prediction takes its nearest candidate (exhaustive).
    """
    kk = du32.shape[0]
    f32 = np.float32
    det = c[0] * r[1] - c[1] * r[0]
    norm = np.hypot(c[0], c[1]) * np.hypot(r[0], r[1])
    good = abs(det) > (2.0 * match_tol + 0.05) * norm
    inv = f32(1.0 / det) if good else f32(0.0)
    c0, c1, r0, r1 = f32(c[0]), f32(c[1]), f32(r[0]), f32(r[1])
    for s in range(8):
        links[s] = -1
    hits = np.zeros(8, np.int64)
    for k in range(kk):
        if not valid[k]:
            continue
        a = np.rint((du32[k] * r1 - dv32[k] * r0) * inv)
        b = np.rint((dv32[k] * c0 - du32[k] * c1) * inv)
        code = f32(3.0) * b + a + f32(4.0)
        if abs(a) > 1 or abs(b) > 1 or code == 4:
            continue
        slot = int(code) - (1 if code > 4 else 0)
        eu = du32[k] - pred_u[slot]
        eu *= eu
        ev = dv32[k] - pred_v[slot]
        ev *= ev
        eu += ev
        if eu < tol2:
            links[slot] = k
            hits[slot] += 1
    clash = False
    for s in range(8):
        clash |= hits[s] > 1
    if good and not clash:
        return
    far = f32(1e6)                                 # a missing candidate: never nearest
    for s in range(8):
        best = np.inf
        at = 0
        for k in range(kk):
            x = du32[k] if valid[k] else far
            y = dv32[k] if valid[k] else far
            e = x - pred_u[s]
            e *= e
            t = y - pred_v[s]
            t *= t
            e += t
            if e < best:
                best = e
                at = k
        links[s] = at if best < tol2 else -1


@kernel("int64[:, ::1](float64[:, ::1], float64[:, ::1], int64[:, ::1], boolean[:, ::1], "
        "float64[:, ::1], float64[:, ::1], float64)")
def neighbour_table(du: np.ndarray, dv: np.ndarray, idx: np.ndarray, valid: np.ndarray,
                    col_vec: np.ndarray, row_vec: np.ndarray, match_tol: float) -> np.ndarray:
    """(N, 9) neighbour table: candidate matching, mutual links, diagonal consistency.

    ``du``, ``dv`` (N, K): displacements to each glyph's k nearest glyphs ``idx`` (those not
    ``valid`` are missing); ``col_vec``, ``row_vec`` (N, 2): local lattice vectors.
    """
    n, kk = du.shape
    nbr = np.full((n, 9), -1, np.int64)
    links = np.empty(8, np.int64)
    pred_u = np.empty(8, np.float32)
    pred_v = np.empty(8, np.float32)
    du32 = np.empty(kk, np.float32)
    dv32 = np.empty(kk, np.float32)
    for i in range(n):
        c = col_vec[i]
        r = row_vec[i]
        local = min(np.hypot(c[0], c[1]), np.hypot(r[0], r[1]))
        t = match_tol * local
        tol2 = t * t
        for s in range(8):
            pred_u[s] = np.float32(_SLOT_DC[s] * c[0] + _SLOT_DR[s] * r[0])
            pred_v[s] = np.float32(_SLOT_DC[s] * c[1] + _SLOT_DR[s] * r[1])
        for k in range(kk):
            du32[k] = np.float32(du[i, k])
            dv32[k] = np.float32(dv[i, k])
        _match_one(du32, dv32, valid[i], pred_u, pred_v, tol2, c, r, match_tol, links)
        nbr[i, 4] = i
        for s in range(8):
            if links[s] >= 0:
                nbr[i, _SLOT_COLUMN[s]] = idx[i, links[s]]
    _mutual(nbr)
    # Diagonals must agree with both two-step paths that exist (they read only the
    # 4-neighbour columns, which this step leaves alone).
    for i in range(n):
        for q in range(4):
            diag, via_row, via_col = _DIAGONALS[q]
            d = nbr[i, diag]
            j = nbr[i, via_row]
            path1 = nbr[j, via_col] if j >= 0 else -1     # (dr, 0) then (0, dc)
            j = nbr[i, via_col]
            path2 = nbr[j, via_row] if j >= 0 else -1     # (0, dc) then (dr, 0)
            if (path1 >= 0 and path1 != d) or (path2 >= 0 and path2 != d):
                nbr[i, diag] = -1
    _mutual(nbr)
    return nbr


@helper
def _axis_steps(du: np.ndarray, dv: np.ndarray, dist: np.ndarray, valid: np.ndarray,
                ax0: float, ax1: float, min_len: float, max_len: float, cos_angle: float
                ) -> tuple[int, int]:
    """One glyph's first candidates within the gates forward and backward along an axis."""
    fwd = -1
    bwd = -1
    for k in range(du.shape[0]):
        if not (valid[k] and dist[k] > min_len and dist[k] < max_len):
            continue
        dot = du[k] * ax0 + dv[k] * ax1
        td = cos_angle * dist[k]
        if fwd < 0 and dot > td:
            fwd = k
        if bwd < 0 and dot < -td:
            bwd = k
    return fwd, bwd


@helper
def _median_of_four_neighbours(old: np.ndarray, nbr4: np.ndarray) -> np.ndarray:
    """Each glyph's vectors: the median over it and its found 4-neighbours (missing: +inf)."""
    n, dims = old.shape
    vec = np.empty_like(old)
    m = np.empty(5, np.float64)
    for i in range(n):
        cnt = 1
        for q in range(4):
            if nbr4[i, q] >= 0:
                cnt += 1
        for d in range(dims):
            m[0] = old[i, d]
            for q in range(4):
                j = nbr4[i, q]
                m[q + 1] = old[j, d] if j >= 0 else np.inf
            for s in range(9):
                a = _SORT5_A[s]
                b = _SORT5_B[s]
                lo = np.minimum(m[a], m[b])
                m[b] = np.maximum(m[a], m[b])
                m[a] = lo
            low = m[2] if cnt >= 5 else (m[1] if cnt >= 3 else m[0])
            high = m[2] if cnt >= 4 else (m[1] if cnt >= 2 else m[0])
            vec[i, d] = 0.5 * (low + high)
    return vec


@kernel("Tuple((float64[:, ::1], int64[:, ::1]))(float64[:, ::1], float64[:, ::1], "
        "float64[:, ::1], boolean[:, ::1], int64[:, ::1], float64[::1], float64[::1], "
        "float64[::1], float64[::1], float64, float64[:, ::1], float64[:, ::1], int64)")
def lattice_vectors(du: np.ndarray, dv: np.ndarray, dist: np.ndarray, valid: np.ndarray,
                    idx: np.ndarray, col_dir: np.ndarray, row_dir: np.ndarray,
                    min_len: np.ndarray, max_len: np.ndarray, cos_angle: float,
                    col_fallback: np.ndarray, row_fallback: np.ndarray,
                    smooth_iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """Local lattice vectors (N, 4: column u, v, row u, v) and 4-neighbours (N, 4), step 3.

    Per glyph, the first (shortest) candidate within the gates along +col, -col, +row, -row
    (angle: dot product beyond ``cos_angle`` x its length; length between ``min_len`` and
    ``max_len``, per glyph); the mean of the forward step and the negated backward step,
    whichever exist, else the fallback vector; then ``smooth_iterations`` medians over each
    glyph and its found 4-neighbours (a 5-value sorting network).  The operations of the
    numpy version it replaced (kept in test_links.py), in their order, element by element:
    the same bits, in one pass without the GIL.
    """
    n = du.shape[0]
    vec = np.empty((n, 4), np.float64)
    nbr4 = np.full((n, 4), -1, np.int64)
    for i in range(n):
        for a in range(2):
            ax = col_dir if a == 0 else row_dir
            fwd, bwd = _axis_steps(du[i], dv[i], dist[i], valid[i], ax[0], ax[1], min_len[i],
                                   max_len[i], cos_angle)
            count = 0.0
            tu = tv = bu = bv = 0.0
            if fwd >= 0:
                count += 1.0
                tu, tv = du[i, fwd], dv[i, fwd]
                nbr4[i, 2 * a] = idx[i, fwd]
            if bwd >= 0:
                count += 1.0
                bu, bv = -du[i, bwd], -dv[i, bwd]
                nbr4[i, 2 * a + 1] = idx[i, bwd]
            fallback = col_fallback if a == 0 else row_fallback
            vec[i, 2 * a] = (tu + bu) / count if count > 0 else fallback[i, 0]
            vec[i, 2 * a + 1] = (tv + bv) / count if count > 0 else fallback[i, 1]
    for _ in range(smooth_iterations):
        vec = _median_of_four_neighbours(vec, nbr4)
    return vec, nbr4


@kernel("Tuple((float64[:, ::1], float64[:, ::1], boolean[:, ::1], int64[:, ::1], float64, "
        "float64[::1]))(float64[::1], float64[::1], float64[:, ::1], int64[:, ::1], int64)")
def lattice_setup(u: np.ndarray, v: np.ndarray, dist: np.ndarray, idx: np.ndarray,
                  step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float,
                                      np.ndarray]:
    """Steps 1-2 of the lattice on a k-NN table: displacements, spacing and orientation.

    ``dist``, ``idx`` (N, K): the k-NN table (``inf``: no candidate).  Returns the
    displacements ``du``, ``dv`` (N, K) to the candidates, which are ``valid``, their indices
    (0 where not valid), the spacing (median distance to the nearest glyph; 0 if none) and
    the unit column direction: the lattice axis closest to +u, from the 4-fold circular mean
    of the short displacements (length 0.5-1.25 spacings) among the first four candidates of
    every ``step``-th glyph, ((1, 0) if there are none).  The 4-fold mean sums
    (c + i s)^4 = cos 4t + i sin 4t of each unit displacement by products, without
    trigonometry (Mardia & Jupp, Directional Statistics, 2000, sec. 2.2.2: the p-th
    trigonometric moment; phi = arg(sum) / 4).
    """
    n, k = dist.shape
    du = np.empty((n, k))
    dv = np.empty((n, k))
    valid = np.empty((n, k), np.bool_)
    out_idx = np.zeros((n, k), np.int64)
    nearest = np.empty(n)
    m = 0
    for i in range(n):
        for j in range(k):
            ok = np.isfinite(dist[i, j])
            valid[i, j] = ok
            t = idx[i, j] if ok else 0
            out_idx[i, j] = t
            du[i, j] = u[t] - u[i]
            dv[i, j] = v[t] - v[i]
        if k > 0 and valid[i, 0]:
            nearest[m] = dist[i, 0]
            m += 1
    spacing = np.median(nearest[:m]) if m else 0.0
    direction = np.array([1.0, 0.0])
    if not (spacing > 0.0 and np.isfinite(spacing)):
        return du, dv, valid, out_idx, spacing, direction
    re = 0.0
    im = 0.0
    found = False
    for i in range(0, n, step):
        for j in range(min(4, k)):
            d = dist[i, j]
            if d > 0.5 * spacing and d < 1.25 * spacing:
                r = np.hypot(du[i, j], dv[i, j])
                if r > 0.0:
                    c = du[i, j] / r
                    s = dv[i, j] / r
                    c2 = c * c - s * s
                    s2 = 2.0 * c * s
                    re += c2 * c2 - s2 * s2
                    im += 2.0 * c2 * s2
                    found = True
    if found:
        phi = np.arctan2(im, re) / 4.0
        direction[0] = np.cos(phi)
        direction[1] = np.sin(phi)
    return du, dv, valid, out_idx, spacing, direction
