"""Neighbourhood recovery on the deformed glyph lattice of one image (no rclpy).

The decoder reads codeword windows, so it needs, for every glyph, which glyph sits one
step right / left / down / up (and diagonally) *on the printed lattice*, even where the pad
is stretched or compressed by contact, where glyphs are missing (occlusion, image border)
and where the extractor reported spurious blobs.

Method (fully vectorised, one k-d tree):

1. k nearest neighbours of every glyph (``cKDTree``).
2. Global lattice orientation from the 4-fold circular mean of the short displacements,
   global spacing from the median nearest-neighbour distance.  The lattice vector closest
   to +u is the column step, the one closest to +v the row step (the sensor's orientation
   is fixed, so the pattern cannot appear rotated by more than 45 degrees).
3. Local lattice vectors per glyph: among its neighbours, the displacement best aligned with
   each of the four global directions (angle and length gates, so strong local stretching
   is followed), averaged forward/backward, then smoothed over the 4-neighbourhood.
4. Each of the 8 neighbours is the candidate closest to the locally predicted position,
   within a tolerance relative to the local spacing.
5. Consistency: links must be mutual (``right(left(i)) == i``) and diagonals must agree with
   the two-step paths through the 4-neighbours; a glyph that more than one glyph claims as
   the same neighbour is dropped from those links.  Missing links are ``-1``: the decoder
   treats them as unknown cells, which costs coverage but never a wrong cell.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

# Offsets of the 3x3 neighbourhood, row-major: index 3 * (dr + 1) + (dc + 1).
OFFSETS = np.array([(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)], dtype=np.int64)
CENTRE = 4


@dataclass
class GridParams:
    """Tolerances of the lattice search (relative to the local glyph spacing)."""

    k_neighbours: int = 11          # candidates considered per glyph (incl. itself)
    init_angle_deg: float = 35.0    # max angle between a displacement and a lattice direction
    init_min_len: float = 0.55      # displacement length gate for the local vectors (x spacing)
    init_max_len: float = 1.8
    match_tol: float = 0.33         # max distance from prediction to candidate (x local spacing)
    smooth_iterations: int = 1      # passes of local-vector smoothing over the 4-neighbourhood


@dataclass
class Grid:
    """Lattice neighbourhood of the glyphs of one image.

    ``nbr[i, 3 * (dr + 1) + (dc + 1)]`` is the index of the glyph one row ``dr`` and one
    column ``dc`` away from glyph ``i`` in image lattice orientation (``dc`` = +1 towards +u),
    or -1; ``nbr[i, 4] == i``.  ``col_vec`` / ``row_vec`` are the local lattice vectors (px).
    """

    nbr: np.ndarray        # (N, 9) int64
    col_vec: np.ndarray    # (N, 2) float64
    row_vec: np.ndarray    # (N, 2) float64
    spacing_px: float
    pts: np.ndarray | None = None   # (N, 2) glyph centres (u, v), pixels

    def neighbour(self, dr: int, dc: int) -> np.ndarray:
        """Index array (N,) of the neighbour at (dr, dc) in {-1, 0, 1}^2, -1 where missing."""
        return self.nbr[:, 3 * (dr + 1) + (dc + 1)]


def _empty(n: int, pts: np.ndarray | None = None) -> Grid:
    nbr = np.full((n, 9), -1, dtype=np.int64)
    nbr[:, CENTRE] = np.arange(n)
    return Grid(nbr, np.zeros((n, 2)), np.zeros((n, 2)), 0.0,
                np.zeros((n, 2)) if pts is None else pts)


def _global_frame(disp: np.ndarray, dist: np.ndarray, spacing: float) -> np.ndarray:
    """Unit column direction (closest lattice axis to +u) from short displacements."""
    short = (dist > 0.5 * spacing) & (dist < 1.25 * spacing)
    d = disp[short]
    if len(d) == 0:
        return np.array([1.0, 0.0])
    theta = np.arctan2(d[:, 1], d[:, 0])
    phi = np.angle(np.exp(4j * theta).sum()) / 4.0   # in (-45, 45] degrees: closest to +u
    return np.array([np.cos(phi), np.sin(phi)])


def _best_four(disp: np.ndarray, dist: np.ndarray, valid: np.ndarray, col_dir: np.ndarray,
               row_dir: np.ndarray, spacing: float, p: GridParams
               ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per glyph, the shortest neighbour step within angle/length gates of +-col, +-row.

    Four (displacement (N, 2) NaN where none, k-NN column (N,) -1 where none) pairs.
    """
    inv = 1.0 / np.maximum(dist, 1e-12)
    cos_c = (disp[..., 0] * col_dir[0] + disp[..., 1] * col_dir[1]) * inv
    cos_r = (disp[..., 0] * row_dir[0] + disp[..., 1] * row_dir[1]) * inv
    gate = valid & (dist > p.init_min_len * spacing) & (dist < p.init_max_len * spacing)
    t = np.cos(np.radians(p.init_angle_deg))
    rows = np.arange(disp.shape[0])
    out = []
    for ok in (cos_c > t, cos_c < -t, cos_r > t, cos_r < -t):
        score = np.where(ok & gate, dist, np.inf)
        k = np.argmin(score, axis=1)
        none = ~np.isfinite(score[rows, k])
        step = disp[rows, k]
        step[none] = np.nan
        out.append((step, np.where(none, -1, k)))
    return out


def _combine(forward: np.ndarray, backward: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Mean of the forward step and the negated backward step, whichever exist."""
    stack = np.stack([forward, -backward])
    have = np.isfinite(stack[..., 0])
    total = np.where(have[..., None], stack, 0.0).sum(axis=0)
    count = have.sum(axis=0)
    out = np.where(count[:, None] > 0, total / np.maximum(count, 1)[:, None], np.nan)
    missing = ~np.isfinite(out[:, 0])
    out[missing] = fallback[missing] if fallback.ndim == 2 else fallback
    return out


def _smooth(vec: np.ndarray, nbr4: np.ndarray) -> np.ndarray:
    """Median of per-glyph vectors (N, D) and their found 4-neighbours' (robust to one bad one)."""
    stack = np.concatenate([vec[:, None, :], np.where((nbr4 >= 0)[..., None],
                                                      vec[np.maximum(nbr4, 0)], np.nan)], axis=1)
    srt = np.sort(stack, axis=1)                       # NaNs sort last
    cnt = np.isfinite(stack[..., 0]).sum(axis=1)       # (N,)
    rows = np.arange(len(vec))
    lo = srt[rows, np.maximum((cnt - 1) // 2, 0)]
    hi = srt[rows, np.maximum(cnt // 2, 0)]
    out = 0.5 * (lo + hi)
    return np.where((cnt > 0)[:, None], out, vec)


def build_grid(u: np.ndarray, v: np.ndarray, params: GridParams | None = None,
               spacing_hint: float = 0.0) -> Grid:
    """Recover the 8-neighbourhood of every glyph centre (u, v) on the deformed lattice."""
    p = params or GridParams()
    pts = np.column_stack([np.asarray(u, np.float64), np.asarray(v, np.float64)])
    n = len(pts)
    if n < 3:
        return _empty(n, pts)
    k = min(p.k_neighbours, n)
    tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)   # faster to build
    bound = 3.0 * spacing_hint if spacing_hint > 0 else np.inf   # only prunes the search
    dist, idx = tree.query(pts, k=k, distance_upper_bound=bound)
    idx = np.where(np.isfinite(dist), idx, 0)          # missing -> masked by `valid`
    dist, idx = dist[:, 1:], idx[:, 1:]               # drop self
    disp = pts[idx] - pts[:, None, :]
    valid = np.isfinite(dist)
    nn = dist[:, 0]
    spacing = float(np.median(nn[np.isfinite(nn)])) if np.isfinite(nn).any() else 0.0
    if not np.isfinite(spacing) or spacing <= 0:
        return _empty(n, pts)
    step = max(1, n // 400)                           # a few hundred glyphs are plenty
    col_dir = _global_frame(disp[::step, :4].reshape(-1, 2), dist[::step, :4].reshape(-1),
                            spacing)
    row_dir = np.array([-col_dir[1], col_dir[0]])     # +v side of the column direction

    # Local lattice vectors, following stretching: the best-aligned neighbour each way.
    steps = _best_four(disp, dist, valid, col_dir, row_dir, spacing, p)
    col_vec = _combine(steps[0][0], steps[1][0], col_dir * spacing)
    row_vec = _combine(steps[2][0], steps[3][0], row_dir * spacing)
    rows = np.arange(n)
    nbr4 = np.stack([np.where(k >= 0, idx[rows, np.maximum(k, 0)], -1) for _, k in steps],
                    axis=1)
    # Smooth them over the 4-neighbourhood (a median: one wrong link does not matter).
    for _ in range(p.smooth_iterations):
        both = _smooth(np.concatenate([col_vec, row_vec], axis=1), nbr4)
        col_vec, row_vec = both[:, :2], both[:, 2:]
    nbr = _assign(pts, disp, idx, valid, col_vec, row_vec, p)
    return Grid(nbr, col_vec, row_vec, spacing, pts)


def _assign(pts: np.ndarray, disp: np.ndarray, idx: np.ndarray, valid: np.ndarray,
            col_vec: np.ndarray, row_vec: np.ndarray, p: GridParams) -> np.ndarray:
    """Neighbour table from local vectors, with mutual and diagonal consistency checks."""
    n = len(pts)
    rows = np.arange(n)
    local = np.minimum(np.linalg.norm(col_vec, axis=1), np.linalg.norm(row_vec, axis=1))
    tol2 = (p.match_tol * local) ** 2
    others = np.array([o for o in range(9) if o != CENTRE])
    # Predicted displacement of every off-centre neighbour, (N, 8, 2); all at once.
    pred = (OFFSETS[others, 1][None, :, None] * col_vec[:, None, :]
            + OFFSETS[others, 0][None, :, None] * row_vec[:, None, :]).astype(np.float32)
    d32 = disp.astype(np.float32)
    d32[~valid] = 1e6                       # missing candidates: never within tolerance
    # Squared distances |disp - pred|^2, (N, 8, K), float32 elementwise (pixels: plenty).
    du = d32[:, None, :, 0] - pred[:, :, None, 0]
    dv = d32[:, None, :, 1] - pred[:, :, None, 1]
    err = du * du
    err += dv * dv
    k = np.argmin(err, axis=2)                                          # (N, 8)
    best = np.take_along_axis(err, k[..., None], axis=2)[..., 0]
    found = np.take_along_axis(idx, k, axis=1)
    nbr = np.full((n, 9), -1, dtype=np.int64)
    nbr[:, CENTRE] = rows
    nbr[:, others] = np.where(best < tol2[:, None], found, -1)
    _mutual(nbr)
    # Diagonals must agree with both two-step paths that exist.
    for o, (dr, dc) in enumerate(OFFSETS):
        if dr == 0 or dc == 0:
            continue
        d = nbr[:, o]
        via_row = nbr[:, 3 * (dr + 1) + 1]        # (dr, 0)
        via_col = nbr[:, 3 + (dc + 1)]            # (0, dc)
        path1 = np.where(via_row >= 0, nbr[np.maximum(via_row, 0), 3 + (dc + 1)], -1)
        path2 = np.where(via_col >= 0, nbr[np.maximum(via_col, 0), 3 * (dr + 1) + 1], -1)
        bad = ((path1 >= 0) & (path1 != d)) | ((path2 >= 0) & (path2 != d))
        nbr[(d >= 0) & bad, o] = -1
    _mutual(nbr)
    return nbr


def _mutual(nbr: np.ndarray) -> None:
    """Keep only mutual links: j = nbr[i, o] requires nbr[j, 8 - o] == i (in place)."""
    rows = np.arange(len(nbr))
    for o in range(9):
        if o == CENTRE:
            continue
        j = nbr[:, o]
        has = j >= 0
        back = np.where(has, nbr[np.maximum(j, 0), 8 - o], -1)
        nbr[has & (back != rows), o] = -1


def window_indices(grid: Grid, window: tuple[int, int]) -> np.ndarray:
    """Glyph indices of every glyph's codeword window, (N, wr * wc), -1 where missing.

    The window is anchored so that the glyph sits at (wr // 2, wc // 2).  Offsets beyond one
    step are reached by walking rows first, then columns; when the columns-first walk also
    arrives, both must agree.
    """
    wr, wc = window
    n = grid.nbr.shape[0]
    out = np.full((n, wr * wc), -1, dtype=np.int64)
    if n == 0:
        return out
    if (wr, wc) == (3, 3):
        return grid.nbr.copy()
    r0, c0 = wr // 2, wc // 2

    def walk(start: np.ndarray, steps: int, o: int) -> np.ndarray:
        cur = start.copy()
        for _ in range(abs(steps)):
            cur = np.where(cur >= 0, grid.nbr[np.maximum(cur, 0), o], -1)
        return cur

    start = np.arange(n)
    for r in range(wr):
        for c in range(wc):
            dr, dc = r - r0, c - c0
            ro = 7 if dr > 0 else 1
            co = 5 if dc > 0 else 3
            a = walk(walk(start, dr, ro), dc, co)
            b = walk(walk(start, dc, co), dr, ro)
            out[:, r * wc + c] = np.where(a < 0, b, np.where((b < 0) | (a == b), a, -1))
    return out
