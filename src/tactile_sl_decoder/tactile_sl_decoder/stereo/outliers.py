"""Geometric outlier rejection: drop points that leave the smooth pad surface.

The decoded points are samples of a smooth surface on the pattern's lattice, so every point
is predicted by its lattice neighbours.  A glyph centre pulled aside in one image (a shadow
edge, a hot spot, a dust speck, an object's texture merging with the ink) changes the
disparity, and a pixel of disparity moves the point by ~0.1 mm in depth (z^2 / (f B) at
15 mm, f 540 px, B 4 mm) while the surface between neighbours 0.5 mm apart bends by
micrometres; a wrong cell puts the point a whole pitch from where its cell should be.

For every cell and each of the four lattice directions (row, column, both diagonals) the
point is predicted from its neighbours along that line: the fourth-order central stencil
(-P[-2] + 4 P[-1] + 4 P[+1] - P[+2]) / 6, exact for cubics (so the curvature of a pressed
sphere leaves no bias), else the mean of the two neighbours, else linear extrapolation from
one side.  The residual is the smallest over the directions (one bad neighbour spoils only
the lines through it), and a point is dropped when it exceeds
``max(min_tolerance_m, mad_factor * 1.4826 * median residual)`` (the frame's own noise
level, so noisy images are not thinned out).  Each pass drops only the worst point of each
5 x 5 neighbourhood (a bad point spoils its neighbours' predictions too), removes it from
the grid and tests again (``passes``), so a cluster of bad points does not shield itself and
its good neighbours are not dropped with it.

All of it works on the (rows, cols) cell grid (numpy; the residuals in numba).  No rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import maximum_filter

from tactile_sl_common.settings import SettingsTable
from tactile_sl_decoder.jit import helper, kernel

DIRECTIONS = ((0, 1), (1, 0), (1, 1), (1, -1))
PAD = 2


@dataclass
class OutlierParams:
    """Tolerances of the surface test (the decoder node exposes them as parameters)."""

    enabled: bool = True
    """Drop points that leave the surface their lattice neighbours define."""
    min_tolerance_m: float = 1e-4
    """Floor of a point's residual tolerance, m (about 1 px of disparity)."""
    mad_factor: float = 8.0
    """Tolerance in robust standard deviations of the frame's residuals."""
    local_factor: float = 2.0
    """... or this many times the neighbours' median residual."""
    passes: int = 6
    """Repeat with the dropped points removed, at most this often."""

    def validate(self) -> "OutlierParams":
        """Raise ValueError naming the first setting outside :data:`OUTLIER_SETTINGS`."""
        OUTLIER_SETTINGS.check(self, "outliers.")
        return self


OUTLIER_SETTINGS = SettingsTable(OutlierParams, ranges={
    "min_tolerance_m": (1e-6, 0.01), "mad_factor": (0.5, 100.0), "local_factor": (0.5, 100.0),
    "passes": (1, 50)})
"""The decoder node's live ``outliers.<field>`` parameters."""


def _shift(grid: np.ndarray, dr: int, dc: int) -> np.ndarray:
    """Grid value at (r + dr, c + dc) for every interior cell (padding is NaN)."""
    rows, cols = grid.shape[0] - 2 * PAD, grid.shape[1] - 2 * PAD
    return grid[PAD + dr:PAD + dr + rows, PAD + dc:PAD + dc + cols]


@helper
def _distance(centre: np.ndarray, pred: np.ndarray) -> float:
    """|centre - pred| as numpy's norm over the last axis sums it: (x^2 + y^2) + z^2."""
    dx = centre[0] - pred[0]
    dy = centre[1] - pred[1]
    dz = centre[2] - pred[2]
    return np.sqrt(dx * dx + dy * dy + dz * dz)


@kernel("float64[:, ::1](float64[:, :, ::1])")
def surface_residuals(grid: np.ndarray) -> np.ndarray:
    """Smallest distance (m) of each cell's point from its neighbours' predictions.

    ``grid``: (rows + 4, cols + 4, 3) points with NaN where no point (two cells of NaN
    padding).  Returns (rows, cols); NaN where no point or no prediction.  Per direction the
    fourth-order stencil where all four neighbours exist, else the two-neighbour mean; the
    one-sided extrapolations only where no direction has either (numba, the arithmetic of
    the numpy expressions it replaced, in their order).
    """
    rows, cols = grid.shape[0] - 2 * PAD, grid.shape[1] - 2 * PAD
    out = np.full((rows, cols), np.nan)
    pred = np.empty(3)
    for r in range(rows):
        for c in range(cols):
            centre = grid[r + PAD, c + PAD]
            if not np.isfinite(centre[0]):
                continue
            best = np.inf
            one_sided = np.inf
            for dr, dc in DIRECTIONS:
                a1 = grid[r + PAD - dr, c + PAD - dc]
                b1 = grid[r + PAD + dr, c + PAD + dc]
                a2 = grid[r + PAD - 2 * dr, c + PAD - 2 * dc]
                b2 = grid[r + PAD + 2 * dr, c + PAD + 2 * dc]
                for k in range(3):
                    p4 = (4.0 * (a1[k] + b1[k]) - a2[k] - b2[k]) / 6.0
                    pred[k] = p4 if np.isfinite(p4) else 0.5 * (a1[k] + b1[k])
                d = _distance(centre, pred)
                if not np.isnan(d) and d < best:      # np.fmin: a NaN never wins
                    best = d
                for k in range(3):
                    pred[k] = 2.0 * a1[k] - a2[k]
                d = _distance(centre, pred)
                if not np.isnan(d) and d < one_sided:
                    one_sided = d
                for k in range(3):
                    pred[k] = 2.0 * b1[k] - b2[k]
                d = _distance(centre, pred)
                if not np.isnan(d) and d < one_sided:
                    one_sided = d
            res = best if np.isfinite(best) else one_sided
            if np.isfinite(res):
                out[r, c] = res
    return out


def surface_outliers(xyz: np.ndarray, row: np.ndarray, col: np.ndarray,
                     shape: tuple[int, int], params: OutlierParams | None = None) -> np.ndarray:
    """Boolean mask of the points that leave the surface their lattice neighbours define.

    ``xyz`` (M, 3) metres, ``row``/``col`` (M,) their cells (unique), ``shape`` the pattern's
    (rows, cols).  Points without any neighbour to judge them by are kept.
    """
    p = params or OutlierParams()
    out = np.zeros(len(xyz), bool)
    if not p.enabled or len(xyz) < 8:
        return out
    rows, cols = shape
    grid = np.full((rows + 2 * PAD, cols + 2 * PAD, 3), np.nan)
    r = np.asarray(row, np.int64) + PAD
    c = np.asarray(col, np.int64) + PAD
    grid[r, c] = xyz
    for _ in range(max(1, p.passes)):
        res_grid = surface_residuals(grid)
        res = res_grid[r - PAD, c - PAD]
        judged = np.isfinite(res) & ~out
        if judged.sum() < 8:
            break
        scale = 1.4826 * float(np.median(res[judged]))
        tol = max(p.min_tolerance_m, p.mad_factor * scale)
        bad = judged & (res > tol)
        if bad.any():
            # A crease (an edge pressed in) bends the surface along a whole line: there the
            # neighbours' residuals are large too, and the point is not an outlier.
            local = _neighbour_median(res_grid)[r - PAD, c - PAD]
            bad &= res > p.local_factor * local
        if not bad.any():
            break
        # Drop only the worst point of each neighbourhood per pass: a bad point also spoils
        # the predictions of its neighbours, which are judged again without it.
        worst = np.zeros((rows, cols))
        worst[r[bad] - PAD, c[bad] - PAD] = res[bad]
        peak = maximum_filter(worst, size=5, mode="constant", cval=0.0)
        bad &= res >= peak[r - PAD, c - PAD]
        out |= bad
        grid[r[bad], c[bad]] = np.nan
    return out


def _neighbour_median(res: np.ndarray) -> np.ndarray:
    """Median of the finite residuals of each cell's 8 neighbours (0 where none)."""
    padded = np.pad(res, 1, constant_values=np.nan)
    rows, cols = res.shape
    stack = np.stack([padded[1 + dr:1 + dr + rows, 1 + dc:1 + dc + cols]
                      for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc])
    finite = np.isfinite(stack)
    ordered = np.sort(np.where(finite, stack, np.inf), axis=0)
    k = finite.sum(axis=0)
    med = np.take_along_axis(ordered, ((np.maximum(k, 1) - 1) // 2)[None], axis=0)[0]
    return np.where(k > 0, med, 0.0)
