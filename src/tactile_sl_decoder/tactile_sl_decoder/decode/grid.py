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

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from tactile_sl_decoder.decode.links import lattice_setup, lattice_vectors, neighbour_table
from tactile_sl_decoder.neighbours import knn_within

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
    local_gates: bool = False
    """Length gates and fallback vectors relative to each glyph's own short and long lattice
    steps (:func:`_local_spacings`) instead of the image's median spacing, and k-NN without
    a distance cap: a view whose glyph spacing varies 2-4 fold across the image (a target
    tilted 40 deg close to the cameras; the calibration's decoder turns it on,
    docs/calibration.md)."""


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
    nearest: np.ndarray | None = None
    """(N,) distance to each glyph's nearest glyph (px, inf: none within the search's gate);
    ``spacing_px`` is its median, and grids joined side by side take the joint median."""

    def neighbour(self, dr: int, dc: int) -> np.ndarray:
        """Index array (N,) of the neighbour at (dr, dc) in {-1, 0, 1}^2, -1 where missing."""
        return self.nbr[:, 3 * (dr + 1) + (dc + 1)]


def _empty(n: int, pts: np.ndarray | None = None) -> Grid:
    nbr = np.full((n, 9), -1, dtype=np.int64)
    nbr[:, CENTRE] = np.arange(n)
    return Grid(nbr, np.zeros((n, 2)), np.zeros((n, 2)), 0.0,
                np.zeros((n, 2)) if pts is None else pts, np.full(n, np.inf))


def _local_spacings(dist: np.ndarray, idx: np.ndarray, valid: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(N, 1) local short and long lattice steps of every glyph.

    The medians, over the glyph and its four nearest glyphs, of the distance to the nearest
    and to the third nearest glyph: on a lattice foreshortened along one axis (steps a < b)
    the neighbours come a, a, b, b, so these are a and b; both are s on a square lattice.
    """
    n = len(dist)
    own = np.arange(n)[:, None]
    near = np.where(valid[:, :4], idx[:, :4], own)
    out = []
    for k in (0, 2):
        d = np.where(np.isfinite(dist[:, k]), dist[:, k], np.nan)
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)   # all-nan rows: fallback
            local = np.nanmedian(np.column_stack([d, d[near]]), axis=1)
            fallback = float(np.nanmedian(d)) if np.isfinite(d).any() else 0.0
        out.append(np.where(np.isfinite(local), local, fallback)[:, None])
    return out[0], np.maximum(out[1], out[0])


def nearest_neighbours(u: np.ndarray, v: np.ndarray, k: int, spacing_hint: float = 0.0
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The ``k - 1`` nearest other glyphs of every glyph: distances (N, k-1), indices.

    Candidates farther than 3 spacings (when ``spacing_hint`` > 0) or beyond the point
    count are ``inf`` (their index is meaningless).  Step 1 of :func:`build_grid`, exposed
    so that it can run per image in a worker thread (GIL released) and be passed to
    :func:`build_grid` as ``neighbours``.  With a spacing hint the search runs on a bucket
    grid (:func:`~tactile_sl_decoder.neighbours.knn_within`, the k-d tree's results bit for
    bit at a third of its cost), without one on a k-d tree.
    """
    x = np.ascontiguousarray(np.asarray(u, np.float64).reshape(-1))
    y = np.ascontiguousarray(np.asarray(v, np.float64).reshape(-1))
    if len(x) == 0:
        return np.zeros((0, max(k - 1, 0))), np.zeros((0, max(k - 1, 0)), dtype=np.intp)
    if spacing_hint > 0:
        dist, idx = knn_within(x, y, max(k, 2), 3.0 * spacing_hint)
        return dist[:, 1:k], idx[:, 1:k]              # drop self
    pts = np.column_stack([x, y])
    tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)   # faster to build
    dist, idx = tree.query(pts, k=max(k, 2))
    return dist[:, 1:k], idx[:, 1:k]                  # drop self


def build_grid(u: np.ndarray, v: np.ndarray, params: GridParams | None = None,
               spacing_hint: float = 0.0,
               neighbours: tuple[np.ndarray, np.ndarray] | None = None) -> Grid:
    """Recover the 8-neighbourhood of every glyph centre (u, v) on the deformed lattice.

    ``neighbours``: the (distances, indices) of :func:`nearest_neighbours` with
    ``k = params.k_neighbours``, if already computed (e.g. per image and offset).
    """
    p = params or GridParams()
    u = np.ascontiguousarray(np.asarray(u, np.float64).reshape(-1))
    v = np.ascontiguousarray(np.asarray(v, np.float64).reshape(-1))
    pts = np.column_stack([u, v])
    n = len(pts)
    if n < 3:
        return _empty(n, pts)
    if neighbours is None:
        neighbours = nearest_neighbours(u, v, min(p.k_neighbours, n), spacing_hint)
    dist = np.ascontiguousarray(neighbours[0], np.float64)
    # displacements to the candidates (contiguous), spacing and orientation in one compiled
    # pass
    du, dv, valid, idx, spacing, col_dir = lattice_setup(
        u, v, dist, np.ascontiguousarray(neighbours[1], np.int64),
        max(1, n // 400))                         # a few hundred glyphs are plenty
    if not np.isfinite(spacing) or spacing <= 0:
        return _empty(n, pts)
    nn = dist[:, 0]
    row_dir = np.array([-col_dir[1], col_dir[0]])     # +v side of the column direction
    short: float | np.ndarray = spacing
    long: float | np.ndarray = spacing
    if p.local_gates:
        short, long = _local_spacings(dist, idx, valid)

    # Local lattice vectors, following stretching: the best-aligned neighbour each way,
    # smoothed over the 4-neighbourhood (a median: one wrong link does not matter); one
    # compiled pass (links.lattice_vectors).
    fallback = spacing if not p.local_gates else np.sqrt(short * long)
    both, _nbr4 = lattice_vectors(
        du, dv, dist, valid, idx, col_dir, row_dir,
        _per_glyph(p.init_min_len * short, n), _per_glyph(p.init_max_len * long, n),
        float(np.cos(np.radians(p.init_angle_deg))),
        np.broadcast_to(col_dir * fallback, (n, 2)).astype(np.float64, order="C"),
        np.broadcast_to(row_dir * fallback, (n, 2)).astype(np.float64, order="C"),
        int(p.smooth_iterations))
    col_vec, row_vec = both[:, :2], both[:, 2:]
    nbr = _assign(du, dv, idx, valid, col_vec, row_vec, p)
    return Grid(nbr, col_vec, row_vec, spacing, pts, np.where(valid[:, 0], nn, np.inf))


def _per_glyph(gate: float | np.ndarray, n: int) -> np.ndarray:
    """A length gate (one value, or (N, 1) per glyph) as an (N,) float64 array."""
    return np.array(np.broadcast_to(np.asarray(gate, np.float64).reshape(-1), (n,)))


NEIGHBOUR_SLOTS = np.array([o for o in range(9) if o != CENTRE])  # nbr columns of the 8 neighbours


def _assign(du: np.ndarray, dv: np.ndarray, idx: np.ndarray, valid: np.ndarray,
            col_vec: np.ndarray, row_vec: np.ndarray, p: GridParams) -> np.ndarray:
    """Neighbour table from local vectors, with mutual and diagonal consistency checks.

    Neighbour (dr, dc) of glyph i is the candidate closest to the predicted displacement
    ``dc * col_vec + dr * row_vec``, if within ``match_tol`` local spacings
    (:func:`~tactile_sl_decoder.decode.links.neighbour_table`).
    """
    return neighbour_table(np.ascontiguousarray(du), np.ascontiguousarray(dv),
                           np.ascontiguousarray(idx, dtype=np.int64),
                           np.ascontiguousarray(valid), np.ascontiguousarray(col_vec),
                           np.ascontiguousarray(row_vec), float(p.match_tol))


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
