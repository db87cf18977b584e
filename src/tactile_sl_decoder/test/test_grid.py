"""Lattice neighbour recovery on synthetic deformed grids with missing and spurious glyphs."""
import numpy as np
import pytest

from tactile_sl_decoder.decode.grid import OFFSETS, build_grid, window_indices


def _lattice(rows=26, cols=32, spacing=18.0, stretch=0.4, angle_deg=7.0, shear=0.0, seed=0,
             missing=0.05, spurious=0.03, noise=0.6):
    """Glyph centres of a lattice with a strong local radial stretch (an indentation)."""
    rng = np.random.default_rng(seed)
    R, C = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    R, C = R.ravel(), C.ravel()
    x = C * spacing + shear * R * spacing
    y = R * spacing
    cx, cy = x.mean(), y.mean()
    d = np.hypot(x - cx, y - cy)
    f = 1 + stretch * np.exp(-(d / (5 * spacing)) ** 2)   # up to +40 % spacing locally
    x, y = cx + (x - cx) * f, cy + (y - cy) * f
    a = np.radians(angle_deg)
    u = 40 + x * np.cos(a) - y * np.sin(a) + rng.normal(0, noise, x.size)
    v = 40 + x * np.sin(a) + y * np.cos(a) + rng.normal(0, noise, x.size)
    keep = rng.random(u.size) >= missing
    u, v, R, C = u[keep], v[keep], R[keep], C[keep]
    ns = int(spurious * u.size)
    su = rng.uniform(u.min(), u.max(), ns)
    sv = rng.uniform(v.min(), v.max(), ns)
    return (np.r_[u, su], np.r_[v, sv], np.r_[R, np.full(ns, -1)], np.r_[C, np.full(ns, -1)])


def _link_stats(grid, R, C):
    good = bad = 0
    for o, (dr, dc) in enumerate(OFFSETS):
        if dr == 0 and dc == 0:
            continue
        j = grid.nbr[:, o]
        m = (j >= 0) & (R >= 0) & (R[np.maximum(j, 0)] >= 0)
        ok = (R[j[m]] == R[m] + dr) & (C[j[m]] == C[m] + dc)
        good += ok.sum()
        bad += (~ok).sum()
    # links that exist in truth: both glyphs present and real
    present = set(zip(R[R >= 0].tolist(), C[R >= 0].tolist()))
    true_links = sum(1 for (r, c) in present for dr, dc in OFFSETS.tolist()
                     if (dr, dc) != (0, 0) and (r + dr, c + dc) in present)
    return good, bad, true_links


@pytest.mark.parametrize("seed,stretch,shear", [(0, 0.4, 0.0), (1, 0.5, 0.15), (2, -0.3, 0.0)])
def test_recovers_links_under_stretch_missing_and_spurious(seed, stretch, shear):
    u, v, R, C = _lattice(seed=seed, stretch=stretch, shear=shear)
    grid = build_grid(u, v)
    good, bad, true_links = _link_stats(grid, R, C)
    assert good >= 0.95 * true_links, (good, true_links)
    assert bad <= 0.002 * true_links, bad


def test_links_are_mutual_and_centre_is_self():
    u, v, R, C = _lattice(seed=4)
    grid = build_grid(u, v)
    n = len(u)
    assert np.array_equal(grid.nbr[:, 4], np.arange(n))
    for o in range(9):
        j = grid.nbr[:, o]
        has = j >= 0
        assert np.array_equal(grid.nbr[j[has], 8 - o], np.flatnonzero(has))


def test_column_direction_follows_plus_u_and_spacing_estimated():
    u, v, R, C = _lattice(seed=5, stretch=0.0, missing=0.0, spurious=0.0, angle_deg=-20)
    grid = build_grid(u, v)
    assert grid.spacing_px == pytest.approx(18.0, rel=0.05)
    right = grid.neighbour(0, 1)
    m = right >= 0
    assert np.all(C[right[m]] == C[m] + 1) and np.all(R[right[m]] == R[m])


def test_larger_windows_are_walked_consistently():
    u, v, R, C = _lattice(seed=6, missing=0.0, spurious=0.0)
    grid = build_grid(u, v)
    idx = window_indices(grid, (5, 5))
    m = idx >= 0
    dr = np.repeat(np.arange(5) - 2, 5)[None, :].repeat(len(u), 0)
    dc = np.tile(np.arange(5) - 2, 5)[None, :].repeat(len(u), 0)
    rows = np.broadcast_to(R[:, None], idx.shape)
    cols = np.broadcast_to(C[:, None], idx.shape)
    assert np.all(R[idx[m]] == rows[m] + dr[m]) and np.all(C[idx[m]] == cols[m] + dc[m])
    assert m.mean() > 0.8


@pytest.mark.parametrize("n", [0, 1, 2])
def test_tiny_inputs_give_no_links(n):
    grid = build_grid(np.arange(n, dtype=float), np.zeros(n))
    assert grid.nbr.shape == (n, 9)
    assert np.all(np.delete(grid.nbr, 4, axis=1) == -1)


def test_precomputed_neighbours_give_the_same_grid():
    from tactile_sl_decoder.decode.grid import GridParams, nearest_neighbours

    u, v, _, _ = _lattice(seed=3)
    ref = build_grid(u, v, spacing_hint=18.0)
    nb = nearest_neighbours(u, v, GridParams().k_neighbours, 18.0)
    got = build_grid(u, v, spacing_hint=18.0, neighbours=nb)
    assert np.array_equal(ref.nbr, got.nbr)
    assert np.array_equal(ref.col_vec, got.col_vec)


def test_smoothing_is_the_median_of_the_found_members():
    from tactile_sl_decoder.decode.links import _median_of_four_neighbours

    rng = np.random.default_rng(0)
    vec = rng.normal(size=(200, 4))
    nbr4 = np.where(rng.random((200, 4)) < 0.3, -1, rng.integers(0, 200, (200, 4)))
    got = _median_of_four_neighbours(vec, nbr4)
    for i in range(200):
        members = np.vstack([vec[i], vec[nbr4[i][nbr4[i] >= 0]]])
        assert np.allclose(got[i], np.median(members, axis=0), rtol=0, atol=1e-15)
