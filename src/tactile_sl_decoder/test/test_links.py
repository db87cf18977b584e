"""The lattice kernels in numba (decode/links.py) equal the numpy versions they replaced.

The numpy versions (the local lattice vectors of step 3, the neighbour table of steps 4-5)
are kept here, verbatim, as the references: on jittered, stretched, sheared lattices with
missing glyphs and stray detections (and, in the digest test, on every bundled bag) both
give the same vectors and table.
"""
import numpy as np
import pytest

from tactile_sl_decoder.decode.grid import (
    CENTRE,
    NEIGHBOUR_SLOTS,
    OFFSETS,
    GridParams,
    _local_spacings,
    _per_glyph,
    nearest_neighbours,
)
from tactile_sl_decoder.decode.links import lattice_setup, lattice_vectors, neighbour_table

# ---- the numpy version of build_grid's step 3 (links.lattice_vectors' reference), verbatim


def _best_four(du: np.ndarray, dv: np.ndarray, dist: np.ndarray, valid: np.ndarray,
               col_dir: np.ndarray, row_dir: np.ndarray, spacing: float | np.ndarray,
               p: GridParams, long_spacing: float | np.ndarray | None = None
               ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per glyph, the shortest neighbour step within angle/length gates of +-col, +-row.

    The gates are ``init_min_len`` x ``spacing`` and ``init_max_len`` x ``long_spacing``
    (default ``spacing``): the image's spacing (a float) or each glyph's short and long
    lattice steps ((N, 1) arrays).

    Four (found (N,) bool, flat index into the (N, K) candidate arrays) pairs, for +col,
    -col, +row, -row.  Candidates come sorted by distance, so the shortest one within the
    gates is the first one.
    """
    n, kk = dist.shape
    long = spacing if long_spacing is None else long_spacing
    gate = valid & (dist > p.init_min_len * spacing) & (dist < p.init_max_len * long)
    td = np.cos(np.radians(p.init_angle_deg)) * dist      # cos(angle) > t  <=>  dot > t |d|
    base = np.arange(n) * kk
    out = []
    for axis in (col_dir, row_dir):
        dot = du * axis[0] + dv * axis[1]
        for ok in (dot > td, dot < -td):
            ok &= gate
            at = base + ok.argmax(axis=1)
            out.append((ok.reshape(-1)[at], at))
    return out


def _combine(du: np.ndarray, dv: np.ndarray, forward: tuple[np.ndarray, np.ndarray],
             backward: tuple[np.ndarray, np.ndarray], fallback: np.ndarray) -> np.ndarray:
    """Mean of the forward step and the negated backward step, whichever exist (N, 2)."""
    (fwd, fat), (bwd, bat) = forward, backward
    flat_u, flat_v = du.reshape(-1), dv.reshape(-1)
    f = fwd[:, None]
    b = bwd[:, None]
    fstep = np.column_stack([flat_u[fat], flat_v[fat]])
    bstep = np.column_stack([flat_u[bat], flat_v[bat]])
    total = np.where(f, fstep, 0.0) + np.where(b, -bstep, 0.0)
    count = f.astype(np.float64) + b
    with np.errstate(invalid="ignore", divide="ignore"):
        out = total / count
    return np.where(count > 0, out, fallback)


_SORT5 = ((0, 1), (3, 4), (2, 4), (2, 3), (0, 3), (0, 2), (1, 4), (1, 3), (1, 2))
"""An optimal sorting network for 5 values (9 compare-exchanges)."""


def _smooth(vec: np.ndarray, nbr4: np.ndarray) -> np.ndarray:
    """Median of per-glyph vectors (N, D) and their found 4-neighbours' (robust to one bad one)."""
    n, dim = vec.shape
    ext = np.vstack([vec, np.full((1, dim), np.inf)])  # a missing neighbour (-1) reads +inf
    m = [vec] + [ext[nbr4[:, k]] for k in range(4)]    # 5 x (N, D), sorted below
    for a, b in _SORT5:
        lo = np.minimum(m[a], m[b])
        m[b] = np.maximum(m[a], m[b])
        m[a] = lo
    cnt = (1 + (nbr4 >= 0).sum(axis=1))[:, None]       # members: the glyph itself and found ones
    lo = np.where(cnt >= 5, m[2], np.where(cnt >= 3, m[1], m[0]))   # index (cnt - 1) // 2
    hi = np.where(cnt >= 4, m[2], np.where(cnt >= 2, m[1], m[0]))   # index cnt // 2
    return 0.5 * (lo + hi)


def local_vectors_reference(du: np.ndarray, dv: np.ndarray, dist: np.ndarray,
                            valid: np.ndarray, idx: np.ndarray, col_dir: np.ndarray,
                            row_dir: np.ndarray, spacing: float | np.ndarray,
                            long: float | np.ndarray, fallback: float | np.ndarray,
                            p: GridParams) -> tuple[np.ndarray, np.ndarray]:
    """Step 3 in numpy, (N, 4) vectors and (N, 4) 4-neighbours: the kernel's reference."""
    steps = _best_four(du, dv, dist, valid, col_dir, row_dir, spacing, p, long)
    col_vec = _combine(du, dv, steps[0], steps[1], col_dir * fallback)
    row_vec = _combine(du, dv, steps[2], steps[3], row_dir * fallback)
    flat_idx = idx.reshape(-1)
    nbr4 = np.column_stack([np.where(found, flat_idx[at], -1) for found, at in steps])
    both = np.concatenate([col_vec, row_vec], axis=1)
    for _ in range(p.smooth_iterations):
        both = _smooth(both, nbr4)
    return both, nbr4


_REVERSE = 8 - NEIGHBOUR_SLOTS
_DIAG = np.array([0, 2, 6, 8])
_DIAG_VIA_ROW = 3 * (OFFSETS[_DIAG, 0] + 1) + 1
_DIAG_VIA_COL = 3 + OFFSETS[_DIAG, 1] + 1
_DIAG_THEN_COL = _DIAG_VIA_COL
_DIAG_THEN_ROW = _DIAG_VIA_ROW
_ODC = OFFSETS[NEIGHBOUR_SLOTS, 1].astype(np.float64)
_ODR = OFFSETS[NEIGHBOUR_SLOTS, 0].astype(np.float64)


def _assign_reference(du: np.ndarray, dv: np.ndarray, idx: np.ndarray, valid: np.ndarray,
            col_vec: np.ndarray, row_vec: np.ndarray, p: GridParams) -> np.ndarray:
    """Neighbour table from local vectors, with mutual and diagonal consistency checks.

    Neighbour (dr, dc) of glyph i is the candidate closest to the predicted displacement
    ``dc * col_vec + dr * row_vec``, if within ``match_tol`` local spacings.  Fast path: each
    candidate's lattice coordinates, rounded, name the only prediction it can be within
    tolerance of (exact while the local vectors are at least ~45 degrees apart, see
    :func:`_match_fast`); glyphs where that does not hold, or where two candidates match the
    same prediction, take the exhaustive (N, 8, K) comparison.  Same result either way.
    """
    n, kk = idx.shape
    rows = np.arange(n)
    local = np.minimum(np.hypot(col_vec[:, 0], col_vec[:, 1]),
                       np.hypot(row_vec[:, 0], row_vec[:, 1]))
    tol2 = (p.match_tol * local) ** 2
    # Predicted displacement of every off-centre neighbour, (N, 8) per axis.
    pred_u = (_ODC * col_vec[:, :1] + _ODR * row_vec[:, :1]).astype(np.float32)
    pred_v = (_ODC * col_vec[:, 1:] + _ODR * row_vec[:, 1:]).astype(np.float32)
    du32 = du.astype(np.float32)
    dv32 = dv.astype(np.float32)
    links, slow = _match_fast(du, dv, du32, dv32, valid, col_vec, row_vec, pred_u, pred_v,
                              tol2, p.match_tol)
    if len(slow):
        miss = ~valid[slow]                       # missing: never within tolerance
        links[slow] = _match_exhaustive(np.where(miss, np.float32(1e6), du32[slow]),
                                        np.where(miss, np.float32(1e6), dv32[slow]),
                                        pred_u[slow], pred_v[slow], tol2[slow])
    found = idx.reshape(-1)[np.maximum(links, 0) + (rows * kk)[:, None]]
    # Neighbour table with a sentinel row n (all -1): a missing link (-1) indexes it.
    nbr = np.full((n + 1, 9), -1, dtype=np.int64)
    nbr[:n, CENTRE] = rows
    nbr[:n, NEIGHBOUR_SLOTS] = np.where(links >= 0, found, -1)
    _mutual(nbr)
    # Diagonals must agree with both two-step paths that exist (the four diagonals read
    # only the 4-neighbour columns, which this step does not change: all at once).
    d = nbr[:n, _DIAG]
    path1 = nbr[nbr[:n, _DIAG_VIA_ROW], _DIAG_THEN_COL]     # (dr, 0) then (0, dc)
    path2 = nbr[nbr[:n, _DIAG_VIA_COL], _DIAG_THEN_ROW]     # (0, dc) then (dr, 0)
    bad = ((path1 >= 0) & (path1 != d)) | ((path2 >= 0) & (path2 != d))
    nbr[:n, _DIAG] = np.where(bad, -1, d)
    _mutual(nbr)
    return nbr[:n]


def _match_exhaustive(du32: np.ndarray, dv32: np.ndarray, pred_u: np.ndarray,
                      pred_v: np.ndarray, tol2: np.ndarray) -> np.ndarray:
    """k-NN column (M, 8) of the candidate nearest each prediction, -1 beyond tolerance."""
    # Squared distances |disp - pred|^2, (M, 8, K), float32 elementwise (pixels: plenty).
    err = np.subtract(du32[:, None, :], pred_u[:, :, None])
    err *= err
    tmp = np.subtract(dv32[:, None, :], pred_v[:, :, None])
    tmp *= tmp
    err += tmp
    k = np.argmin(err, axis=2)                                          # (M, 8)
    best = np.take_along_axis(err, k[..., None], axis=2)[..., 0]
    return np.where(best < tol2[:, None], k, -1)


def _match_fast(du: np.ndarray, dv: np.ndarray, du32: np.ndarray, dv32: np.ndarray,
                valid: np.ndarray, col_vec: np.ndarray, row_vec: np.ndarray,
                pred_u: np.ndarray, pred_v: np.ndarray, tol2: np.ndarray, match_tol: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Candidate matching through lattice coordinates; (links (N, 8), glyphs to redo).

    A candidate within ``tol = match_tol * min(|c|, |r|)`` of the prediction ``(a, b)`` (in
    steps of c = col_vec, r = row_vec) has lattice coordinates within ``tol / (min(|c|, |r|)
    sin(angle(c, r)))`` of ``(a, b)`` per axis, i.e. below 0.5 when ``sin > 2 * match_tol``
    (with margin): rounding its coordinates then names that prediction, and only it.  The
    squared distance is computed exactly as in :func:`_match_exhaustive` (float32), so where
    each prediction has at most one candidate within tolerance the links are identical.
    """
    n, kk = du.shape
    c0, c1 = col_vec[:, 0:1], col_vec[:, 1:2]
    r0, r1 = row_vec[:, 0:1], row_vec[:, 1:2]
    det = c0 * r1 - c1 * r0                                       # (N, 1)
    norm = np.hypot(c0, c1) * np.hypot(r0, r1)
    good = np.abs(det[:, 0]) > (2.0 * match_tol + 0.05) * norm[:, 0]
    inv = np.where(good[:, None], 1.0 / np.where(good[:, None], det, 1.0), 0.0)
    # Lattice coordinates in float32: only their rounding matters, with a wide margin.
    f32 = np.float32
    inv = inv.astype(f32)
    a = np.rint((du32 * r1.astype(f32) - dv32 * r0.astype(f32)) * inv)   # column steps
    b = np.rint((dv32 * c0.astype(f32) - du32 * c1.astype(f32)) * inv)   # row steps
    code = 3 * b + a + 4                                          # 3 * (dr + 1) + (dc + 1)
    ok = valid & (np.abs(a) <= 1) & (np.abs(b) <= 1) & (code != CENTRE)
    slot = np.where(ok, code - (code > CENTRE), 0).astype(np.intp)   # 0..7 (NEIGHBOUR_SLOTS order)
    flat = slot + (np.arange(n) * 8)[:, None]
    eu = du32 - pred_u.reshape(-1)[flat]
    eu *= eu
    ev = dv32 - pred_v.reshape(-1)[flat]
    ev *= ev
    eu += ev
    ok &= eu < tol2[:, None]
    hit_flat = flat[ok]
    links = np.full(n * 8, -1, dtype=np.intp)
    links[hit_flat] = np.nonzero(ok)[1]
    # Two candidates within tolerance of one prediction: take the exhaustive path there.
    clash = np.bincount(hit_flat, minlength=n * 8) > 1
    redo = ~good
    if clash.any():
        redo |= clash.reshape(n, 8).any(axis=1)
    return links.reshape(n, 8), np.flatnonzero(redo)


def _mutual(nbr: np.ndarray) -> None:
    """Keep only mutual links: j = nbr[i, o] requires nbr[j, 8 - o] == i (in place).

    ``nbr`` has a sentinel last row of -1 (indexed by missing links).  All offsets at once:
    the same as one offset after the other, since a link and its reverse are judged alike.
    """
    n = len(nbr) - 1
    j = nbr[:n, NEIGHBOUR_SLOTS]
    back = nbr[j, _REVERSE]                       # j = -1 reads the sentinel row
    keep = back == np.arange(n)[:, None]
    nbr[:n, NEIGHBOUR_SLOTS] = np.where(keep, j, -1)



def _lattice(seed, shear, stretch, drop, strays, oblique=False):
    """Glyph centres (u, v) of a deformed synthetic lattice, with gaps and stray points."""
    rng = np.random.default_rng(seed)
    r, c = np.mgrid[0:27, 0:28]
    a = np.array([[stretch, shear], [0.0, 1.0]]) if not oblique else np.array(
        [[1.0, 0.9], [0.0, 0.45]])
    pts = 18.0 * np.column_stack([c.ravel(), r.ravel()]) @ a.T + rng.normal(0, 1.2, (756, 2))
    pts = pts[rng.random(len(pts)) >= drop]
    pts = np.vstack([pts, rng.uniform(0, 480, (strays, 2))])
    return pts[:, 0], pts[:, 1]


def _global_frame(du, dv, dist, spacing):
    """Unit column direction from short displacements: the trigonometric version that
    links.lattice_setup replaced (its reference to within rounding)."""
    short = (dist > 0.5 * spacing) & (dist < 1.25 * spacing)
    if not short.any():
        return np.array([1.0, 0.0])
    theta = np.arctan2(dv[short], du[short])
    phi = np.angle(np.exp(4j * theta).sum()) / 4.0   # in (-45, 45] degrees: closest to +u
    return np.array([np.cos(phi), np.sin(phi)])


def _candidates(u, v, p, hint):
    """build_grid's steps 1-2: k-NN, displacements, spacing and the global frame."""
    dist, idx = nearest_neighbours(u, v, p.k_neighbours, hint)
    valid = np.isfinite(dist)
    idx = np.where(valid, idx, 0)
    du = u[idx] - u[:, None]
    dv = v[idx] - v[:, None]
    spacing = float(np.median(dist[:, 0][valid[:, 0]]))
    col_dir = _global_frame(du[:, :4], dv[:, :4], dist[:, :4], spacing)
    return dist, idx, valid, du, dv, spacing, col_dir, np.array([-col_dir[1], col_dir[0]])


def _inputs(seed, shear, stretch, drop, strays, oblique=False):
    """What build_grid hands _assign, for a deformed synthetic lattice."""
    u, v = _lattice(seed, shear, stretch, drop, strays, oblique)
    p = GridParams()
    dist, idx, valid, du, dv, spacing, col_dir, row_dir = _candidates(u, v, p, 18.0)
    both, _nbr4 = local_vectors_reference(du, dv, dist, valid, idx, col_dir, row_dir, spacing,
                                          spacing, spacing, p)
    return du, dv, idx, valid, both[:, :2], both[:, 2:], p


@pytest.mark.parametrize("seed,shear,stretch,drop,strays,oblique", [
    (0, 0.0, 1.0, 0.0, 0, False), (1, 0.15, 1.2, 0.1, 30, False),
    (2, -0.3, 0.8, 0.3, 80, False), (3, 0.0, 1.0, 0.05, 10, True)])
def test_numba_table_equals_the_numpy_reference(seed, shear, stretch, drop, strays, oblique):
    du, dv, idx, valid, col_vec, row_vec, p = _inputs(seed, shear, stretch, drop, strays,
                                                      oblique)
    want = _assign_reference(du, dv, idx, valid, col_vec, row_vec, p)
    got = neighbour_table(du, dv, idx.astype(np.int64), valid, np.ascontiguousarray(col_vec),
                          np.ascontiguousarray(row_vec), p.match_tol)
    assert np.array_equal(got, want)
    assert (got[:, CENTRE] == np.arange(len(got))).all() and (got[:, :4] >= 0).any()


@pytest.mark.parametrize("seed,shear", [(0, 0.0), (1, 0.3), (2, -0.3)])
def test_fast_matching_equals_exhaustive_matching(seed, shear):
    """Candidate matching via rounded lattice coordinates == the (N, 8, K) comparison."""
    du, dv, idx, valid, col_vec, row_vec, p = _inputs(seed, shear, 1.0, 0.1, 50)
    local = np.minimum(np.hypot(col_vec[:, 0], col_vec[:, 1]),
                       np.hypot(row_vec[:, 0], row_vec[:, 1]))
    tol2 = (p.match_tol * local) ** 2
    pred_u = (_ODC * col_vec[:, :1] + _ODR * row_vec[:, :1]).astype(np.float32)
    pred_v = (_ODC * col_vec[:, 1:] + _ODR * row_vec[:, 1:]).astype(np.float32)
    du32, dv32 = du.astype(np.float32), dv.astype(np.float32)
    links, redo = _match_fast(du, dv, du32, dv32, valid, col_vec, row_vec, pred_u, pred_v,
                              tol2, p.match_tol)
    miss = ~valid
    ref = _match_exhaustive(np.where(miss, np.float32(1e6), du32),
                            np.where(miss, np.float32(1e6), dv32), pred_u, pred_v, tol2)
    fast = links.copy()
    fast[redo] = ref[redo]
    assert np.array_equal(fast, ref) and len(redo) < len(links) // 2


@pytest.mark.parametrize("seed,shear,stretch,drop,strays,oblique,local_gates,smooth", [
    (0, 0.0, 1.0, 0.0, 0, False, False, 1), (1, 0.15, 1.2, 0.1, 30, False, False, 2),
    (2, -0.3, 0.8, 0.3, 80, False, True, 1), (3, 0.0, 1.0, 0.05, 10, True, True, 0),
    (4, 0.1, 1.6, 0.2, 40, False, True, 3)])
def test_lattice_vectors_kernel_equals_the_numpy_steps(seed, shear, stretch, drop, strays,
                                                      oblique, local_gates, smooth):
    """Step 3 of build_grid in numba == _best_four, _combine and _smooth, bit for bit."""
    u, v = _lattice(seed, shear, stretch, drop, strays, oblique)
    p = GridParams(local_gates=local_gates, smooth_iterations=smooth)
    dist, idx, valid, du, dv, spacing, col_dir, row_dir = _candidates(
        u, v, p, 0.0 if local_gates else 18.0)
    short = long = spacing
    if local_gates:
        short, long = _local_spacings(dist, idx, valid)
    fallback = spacing if not local_gates else np.sqrt(short * long)
    want_vec, want_nbr4 = local_vectors_reference(du, dv, dist, valid, idx, col_dir, row_dir,
                                                  short, long, fallback, p)
    n = len(u)
    got_vec, got_nbr4 = lattice_vectors(
        du, dv, np.ascontiguousarray(dist), valid, idx.astype(np.int64), col_dir, row_dir,
        _per_glyph(p.init_min_len * short, n), _per_glyph(p.init_max_len * long, n),
        float(np.cos(np.radians(p.init_angle_deg))),
        np.broadcast_to(col_dir * fallback, (n, 2)).copy(),
        np.broadcast_to(row_dir * fallback, (n, 2)).copy(), smooth)
    assert np.array_equal(got_nbr4, want_nbr4) and (got_nbr4 >= 0).mean() > 0.5
    np.testing.assert_array_equal(got_vec, want_vec)


@pytest.mark.parametrize("seed,shear,stretch,drop,strays,oblique", [
    (0, 0.0, 1.0, 0.0, 0, False), (1, 0.15, 1.2, 0.1, 30, False),
    (2, -0.3, 0.8, 0.3, 80, False), (3, 0.0, 1.0, 0.05, 10, True)])
def test_lattice_setup_equals_the_numpy_steps(seed, shear, stretch, drop, strays, oblique):
    """Displacements, validity and spacing bit for bit; the orientation (products instead
    of trigonometry) to rounding."""
    u, v = _lattice(seed, shear, stretch, drop, strays, oblique)
    p = GridParams()
    dist, idx, valid, du, dv, spacing, col_dir, _row = _candidates(u, v, p, 18.0)
    raw = nearest_neighbours(u, v, p.k_neighbours, 18.0)
    got = lattice_setup(np.ascontiguousarray(u, np.float64), np.ascontiguousarray(v, np.float64),
                        np.ascontiguousarray(raw[0]), np.ascontiguousarray(raw[1], np.int64), 1)
    for mine, ref in zip(got[:4], (du, dv, valid, idx)):
        np.testing.assert_array_equal(mine, ref)
    assert got[4] == spacing
    np.testing.assert_allclose(got[5], col_dir, rtol=0, atol=1e-12)
    # every other glyph (the subsample of large images) and a table with no short step
    half = lattice_setup(np.ascontiguousarray(u, np.float64), np.ascontiguousarray(v, np.float64),
                         np.ascontiguousarray(raw[0]), np.ascontiguousarray(raw[1], np.int64),
                         2)[5]
    np.testing.assert_allclose(half, _global_frame(du[::2, :4], dv[::2, :4], dist[::2, :4],
                                                   spacing), rtol=0, atol=1e-12)
    far = lattice_setup(np.array([0.0, 100.0, 300.0]), np.zeros(3),
                        np.array([[100.0, 300.0], [100.0, 200.0], [200.0, 300.0]]),
                        np.array([[1, 2], [0, 2], [1, 0]]), 1)
    assert far[4] == 100.0 and tuple(far[5]) == (1.0, 0.0)
