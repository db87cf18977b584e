"""Contact area from where a non-negative traction presses: any indenter shape (no rclpy).

The traction map of :mod:`.traction` is smooth over about a cell, and the share of its peak
above which a cell is in contact depends on the indenter: a sphere's pressure falls to zero at
the edge of the contact, a flat punch's is infinite there, so no one threshold suits both (a
threshold calibrated on spheres put a flat punch's area 100 % too high).  Instead the area is
taken from the *support* of a second inversion, constrained to press (p >= 0,
:meth:`~tactile_sl_decoder.touch.traction.TractionSolver.support_pressure`): outside the
contact the surface is free of traction, and with the constraint the inversion puts no
pressure there.  A cell is in the support when its pressure exceeds ``sigmas`` times its own
noise (the displacement noise propagated through the inversion).

Cells the edge of the contact cuts count with the share of them that is in contact.  Near an
edge the pressure of a frictionless contact goes as p ~ d^beta, d the distance inside the edge
(Johnson, Contact Mechanics, 1985, ch. 4-5: beta = 1/2 where a smooth body's surface leaves the
pad, beta = -1/2 at the sharp rim of a flat punch; beta = 0 for a uniform pressure).  Along the
normal to the edge, a cell of unit width covered over c (0 < c < 1) carries
F0 = c^(beta+1) / (beta+1) and its fully covered inward neighbour
F1 = ((c+1)^(beta+1) - c^(beta+1)) / (beta+1), so the ratio F0 / F1 gives c
(:func:`edge_coverage`); the exponent of a region comes from its first two inner rings of
cells (:func:`edge_exponent`: the ratio of their forces at c = 1/2 is 1.45 for beta = -1/2,
1 for 0 and 0.70 for 1/2).  A region too thin for two inner rings takes beta = 0 (a cell's
share is its force over its neighbour's).  Cells just outside the support (too weak to stand
out of the noise) take their share by the same rule.

Where the pressure near the edge does not stand out of the noise (``edge_snr``: the mean
pressure of the first inner ring over its noise) the support cannot locate the edge; such a
region is not used and the contact state falls back on the map's threshold
(:func:`~tactile_sl_decoder.touch.contact.contact_state`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile_sl_decoder.jit import helper, kernel

BETAS = np.linspace(-0.5, 0.5, 41)
"""Edge exponents tabulated (sharp rim ... smooth edge)."""
THIN_BETA = 0.0
"""Edge exponent of a region too thin for two inner rings (uniform pressure)."""
_COVER = np.linspace(0.0, 1.0, 401)


def edge_ratio(coverage: np.ndarray, beta: float) -> np.ndarray:
    """F0 / F1 of a cell the edge cuts at ``coverage`` and its inward neighbour (1-D edge law)."""
    c = np.asarray(coverage, np.float64)
    b = beta + 1.0
    return c ** b / ((c + 1.0) ** b - c ** b)


def ring_ratio(beta: np.ndarray | float, coverage: float = 0.5) -> np.ndarray:
    """Force of the first inner ring over the second's, the edge cutting the boundary at c."""
    b = np.asarray(beta, np.float64) + 1.0
    c = coverage
    return ((c + 1) ** b - c ** b) / ((c + 2) ** b - (c + 1) ** b)


_RING = ring_ratio(BETAS)                                   # decreasing in beta
_BETA_INDEX = np.arange(len(BETAS), dtype=np.float64)
_RATIO_AXIS = np.concatenate([[0.0], np.geomspace(1e-4, 1e3, 600)])
# coverage as a function of (beta index, ratio): the inverse of edge_ratio, row by row
_COVERAGE = np.stack([np.interp(_RATIO_AXIS, edge_ratio(_COVER, float(b)), _COVER)
                      for b in BETAS])


def edge_exponent(ring_ratio_value: float) -> float:
    """The edge exponent beta in [-1/2, 1/2] whose first-to-second ring ratio is the given one."""
    return float(np.interp(ring_ratio_value, _RING[::-1], BETAS[::-1]))


def edge_coverage(ratio: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """Share in contact of cells whose force is ``ratio`` times their inward neighbour's.

    ``beta`` per cell (the edge exponent of its region); bilinear in the tabulated exponents
    and ratios (clipped to [0, 1]).
    """
    r = np.clip(np.asarray(ratio, np.float64), 0.0, _RATIO_AXIS[-1])
    x = np.interp(np.asarray(beta, np.float64), BETAS, np.arange(len(BETAS)))
    i0 = np.minimum(x.astype(np.intp), len(BETAS) - 2)
    t = x - i0
    j = np.clip(np.searchsorted(_RATIO_AXIS, r) - 1, 0, len(_RATIO_AXIS) - 2)
    s = (r - _RATIO_AXIS[j]) / (_RATIO_AXIS[j + 1] - _RATIO_AXIS[j])
    lo = _COVERAGE[i0, j] * (1 - s) + _COVERAGE[i0, j + 1] * s
    hi = _COVERAGE[i0 + 1, j] * (1 - s) + _COVERAGE[i0 + 1, j + 1] * s
    return np.clip(lo * (1 - t) + hi * t, 0.0, 1.0)


@dataclass
class SupportRegions:
    """The contact regions of a constrained traction map, on the cell grid."""

    labels: np.ndarray     # (rows, cols) int32: region 1..n of cells counted (0: none)
    share: np.ndarray      # (rows, cols) share of each cell in contact (0 where labels is 0)
    support: np.ndarray    # (rows, cols) bool: the cells pressing above their noise
    area_cells: np.ndarray  # (n + 1,) area of each region in cells (index 0 unused)
    cells: np.ndarray      # (n + 1,) cells of the support in each region
    edge_snr: np.ndarray   # (n + 1,) first inner ring's pressure over its noise
    beta: np.ndarray       # (n + 1,) edge exponent
    peak: np.ndarray       # (n + 1,) flat grid index of each region's largest pressure


def support_regions(pressure: np.ndarray, noise: np.ndarray, sigmas: float) -> SupportRegions:
    """Contact regions and the share in contact of each cell (see the module docstring).

    ``pressure`` (rows, cols) >= 0 (N per cell, 0 where unknown) and ``noise`` (rows, cols) its
    standard deviation (inf where unknown).  Compiled (numba): a cell grid of a few hundred
    cells, several passes.
    """
    p = np.ascontiguousarray(pressure, dtype=np.float64)
    sig = np.ascontiguousarray(noise, dtype=np.float64)
    labels, share, support, area, cells, snr, beta, peak = _support_regions(p, sig,
                                                                          float(sigmas))
    return SupportRegions(labels, share, support, area, cells, snr, beta, peak)


@helper
def _coverage(ratio: float, beta: float) -> float:
    """:func:`edge_coverage` of one cell."""
    r = min(max(ratio, 0.0), _RATIO_AXIS[-1])
    x = np.interp(beta, BETAS, _BETA_INDEX)
    i0 = min(int(x), len(BETAS) - 2)
    t = x - i0
    j = np.searchsorted(_RATIO_AXIS, r) - 1
    j = min(max(j, 0), len(_RATIO_AXIS) - 2)
    s = (r - _RATIO_AXIS[j]) / (_RATIO_AXIS[j + 1] - _RATIO_AXIS[j])
    lo = _COVERAGE[i0, j] * (1 - s) + _COVERAGE[i0, j + 1] * s
    hi = _COVERAGE[i0 + 1, j] * (1 - s) + _COVERAGE[i0 + 1, j + 1] * s
    return min(max(lo * (1 - t) + hi * t, 0.0), 1.0)


@helper
def _label(support: np.ndarray) -> tuple[np.ndarray, int]:
    """8-connected regions numbered 1.. in the order of their first cell (row-major)."""
    rows, cols = support.shape
    labels = np.zeros((rows, cols), np.int32)
    stack = np.empty(rows * cols, np.int64)
    count = 1
    for start in range(rows * cols):
        r0, c0 = start // cols, start % cols
        if not support[r0, c0] or labels[r0, c0] != 0:
            continue
        labels[r0, c0] = count
        top = 0
        stack[0] = start
        while top >= 0:
            i = stack[top]
            top -= 1
            r, c = i // cols, i % cols
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    rr, cc = r + dr, c + dc
                    if (0 <= rr < rows and 0 <= cc < cols and support[rr, cc]
                            and labels[rr, cc] == 0):
                        labels[rr, cc] = count
                        top += 1
                        stack[top] = rr * cols + cc
        count += 1
    return labels, count


@helper
def _eroded(mask: np.ndarray) -> np.ndarray:
    """Cells of ``mask`` whose 4 neighbours are all in it (outside the grid: not)."""
    rows, cols = mask.shape
    out = np.zeros((rows, cols), np.bool_)
    for r in range(1, rows - 1):
        for c in range(1, cols - 1):
            out[r, c] = (mask[r, c] and mask[r - 1, c] and mask[r + 1, c] and mask[r, c - 1]
                         and mask[r, c + 1])
    return out


@helper
def _neighbour_mean(values: np.ndarray, mask: np.ndarray, r: int, c: int
                    ) -> tuple[float, int, int]:
    """Mean of ``values`` over (r, c)'s 4 neighbours in ``mask``, their count, the largest.

    0, 0 and -1 (flat index of the largest) without any.
    """
    rows, cols = values.shape
    total, m, best, at = 0.0, 0, -1.0, -1
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        rr, cc = r + dr, c + dc
        if 0 <= rr < rows and 0 <= cc < cols and mask[rr, cc]:
            total += values[rr, cc]
            m += 1
            if values[rr, cc] > best:
                best, at = values[rr, cc], rr * cols + cc
    return (total / m if m else 0.0), m, at


@helper
def _region_figures(pressure: np.ndarray, noise: np.ndarray, labels: np.ndarray, count: int,
                    inner: np.ndarray, core: np.ndarray) -> tuple:
    """Per region: support cells, peak cell, edge exponent and the edge's signal to noise."""
    rows, cols = pressure.shape
    cells = np.zeros(count, np.int64)
    peak = np.zeros(count, np.int64)
    beta = np.full(count, THIN_BETA)
    snr = np.zeros(count)
    sums = np.zeros((7, count))  # ring n, f, s; core n, f; all f, s
    best = np.full(count, -1.0)
    for r in range(rows):
        for c in range(cols):
            k = labels[r, c]
            if k == 0:
                continue
            s = noise[r, c] if np.isfinite(noise[r, c]) else 0.0
            sums[5, k] += pressure[r, c]
            sums[6, k] += s
            cells[k] += 1
            if pressure[r, c] > best[k]:
                best[k] = pressure[r, c]
                peak[k] = r * cols + c
            if core[r, c]:
                sums[3, k] += 1
                sums[4, k] += pressure[r, c]
            elif inner[r, c]:
                sums[0, k] += 1
                sums[1, k] += pressure[r, c]
                sums[2, k] += s
    for k in range(1, count):
        if sums[0, k] > 0 and sums[3, k] > 0 and sums[4, k] > 0:
            rho = (sums[1, k] / sums[0, k]) / (sums[4, k] / sums[3, k])
            beta[k] = np.interp(rho, _RING[::-1], BETAS[::-1])
        if sums[0, k] > 0:
            snr[k] = sums[1, k] / sums[2, k] if sums[2, k] > 0 else np.inf
        else:
            snr[k] = sums[5, k] / sums[6, k] if sums[6, k] > 0 else np.inf
    return cells, peak, beta, snr


@kernel("Tuple((int32[:, ::1], float64[:, ::1], boolean[:, ::1], float64[::1], int64[::1], "
        "float64[::1], float64[::1], int64[::1]))(float64[:, ::1], float64[:, ::1], float64)")
def _support_regions(pressure: np.ndarray, noise: np.ndarray, sigmas: float) -> tuple:
    """The passes of :func:`support_regions` over the cell grid."""
    rows, cols = pressure.shape
    support = np.zeros((rows, cols), np.bool_)
    for r in range(rows):
        for c in range(cols):
            support[r, c] = pressure[r, c] > sigmas * noise[r, c]
    labels, count = _label(support)
    share = np.zeros((rows, cols))
    area = np.zeros(count)
    if count == 1:
        z = np.zeros(count, np.int64)
        return labels, share, support, area, z, np.zeros(count), np.full(count, THIN_BETA), z
    inner = _eroded(support)
    core = _eroded(inner)
    cells, peak, beta, snr = _region_figures(pressure, noise, labels, count, inner, core)
    owner = np.zeros((rows, cols), np.int32)
    for r in range(rows):
        for c in range(cols):
            k = labels[r, c]
            if k != 0:
                if inner[r, c]:
                    share[r, c] = 1.0
                    continue
                # a cell the edge cuts: its force over its inner neighbours' mean
                mean, m, _ = _neighbour_mean(pressure, inner, r, c)
                share[r, c] = _coverage(pressure[r, c] / mean, beta[k]) if mean > 0 else 1.0
            elif pressure[r, c] > 0:
                # just outside the support: over its neighbours' in it, with the region of
                # the one pressing hardest
                mean, m, at = _neighbour_mean(pressure, support, r, c)
                if mean > 0:
                    owner[r, c] = labels[at // cols, at % cols]
                    share[r, c] = _coverage(pressure[r, c] / mean, beta[owner[r, c]])
    for r in range(rows):
        for c in range(cols):
            if owner[r, c] != 0:
                labels[r, c] = owner[r, c]
            area[labels[r, c]] += share[r, c]
    area[0] = 0.0
    return labels, share, support, area, cells, snr, beta, peak


@helper
def _edge_ring(clear: np.ndarray, rows: np.ndarray, cols: np.ndarray, grid_rows: int,
               grid_cols: int) -> np.ndarray:
    """Positions of the cells within one cell of a ``clear`` cell and of one that is not.

    Outside the grid counts as clear (a 3x3 dilation minus a 3x3 erosion).
    """
    n = len(rows)
    grid = np.zeros((grid_rows, grid_cols), np.bool_)
    for k in range(n):
        if clear[k]:
            grid[rows[k], cols[k]] = True
    ring = np.empty(n, np.int64)
    m = 0
    for k in range(n):
        grown, eroded = False, True
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                rr, cc = rows[k] + dr, cols[k] + dc
                if 0 <= rr < grid_rows and 0 <= cc < grid_cols:
                    if grid[rr, cc]:
                        grown = True
                    else:
                        eroded = False
        if grown and not eroded:
            ring[m] = k
            m += 1
    return ring[:m]


@helper
def cholesky_solve(a: np.ndarray, b: np.ndarray) -> bool:
    """Solve a x = b in place (b <- x, a overwritten) for a symmetric positive definite a.

    Cholesky a = L L^T (Golub and Van Loan, Matrix Computations, 4th ed., alg. 4.2.1), from
    a's lower triangle; then the two triangular solves.  False when a pivot is not positive.
    """
    n = a.shape[0]
    for j in range(n):
        d = a[j, j]
        for k in range(j):
            d -= a[j, k] * a[j, k]
        if d <= 0.0:
            return False
        d = np.sqrt(d)
        a[j, j] = d
        for i in range(j + 1, n):
            total = a[i, j]
            for k in range(j):
                total -= a[i, k] * a[j, k]
            a[i, j] = total / d
    for i in range(n):
        total = b[i]
        for k in range(i):
            total -= a[i, k] * b[k]
        b[i] = total / a[i, i]
    for i in range(n - 1, -1, -1):
        total = b[i]
        for k in range(i + 1, n):
            total -= a[k, i] * b[k]
        b[i] = total / a[i, i]
    return True


@helper
def _transposed_block(inverse: np.ndarray, ring: np.ndarray, at: np.ndarray) -> np.ndarray:
    """M[ring[at], ring[at]]^T (M read along its rows)."""
    h = len(at)
    block = np.empty((h, h))
    for j in range(h):
        for i in range(h):
            block[i, j] = inverse[ring[at[j]], ring[at[i]]]
    return block


@helper
def _held_response(inverse: np.ndarray, ring: np.ndarray, at: np.ndarray,
                   nu: np.ndarray) -> np.ndarray:
    """M[ring, ring[at]] @ nu, M symmetric (read along its rows, one per held cell)."""
    out = np.zeros(len(ring))
    for j in range(len(at)):
        row = inverse[ring[at[j]]]
        for i in range(len(ring)):
            out[i] += row[ring[i]] * nu[j]
    return out


@kernel("float64[::1](float64[::1], boolean[::1], int64[::1], int64[::1], int64, int64, "
        "float64[:, ::1], int64[::1], int64)")
def constrained_edge(free: np.ndarray, clear: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                     grid_rows: int, grid_cols: int, inverse: np.ndarray, cells: np.ndarray,
                     max_rounds: int) -> np.ndarray:
    """The pressure ``free`` of cells near a contact, held >= 0 at the edge of the ``clear``.

    ``free`` (window,) is the unconstrained pressure of the window's cells (``cells``: their
    indices into ``inverse``, ``rows``/``cols``: their places on the grid), ``clear`` marks
    those that clearly press.  Only the ring at the edge of the clear cells (the window's
    cells within one cell of a clear cell and of a cell that is not; outside the grid
    counts as clear) is held >= 0 (the ringing of the unconstrained inversion around a
    contact is what the constraint removes).  With the ring's cells N held at zero,
    p = p0 + M[:, N] nu and M[N, N] nu = -p0[N], M = ``inverse`` (the normal block of the
    constrained inversion's inverse, symmetric); a held cell whose multiplier nu pulls is
    released, a free one that would pull is held (Lawson and Hanson, Solving Least Squares
    Problems, 1974, ch. 23, in the dual form), for at most ``max_rounds`` rounds.  Returns
    the window's pressure (the ring's constrained, the others as given; not clipped).
    """
    p = free.copy()
    ring_at = _edge_ring(clear, rows, cols, grid_rows, grid_cols)
    m = len(ring_at)
    if m == 0:
        return p
    ring = cells[ring_at]
    free_ring = free[ring_at]
    scale = np.abs(free_ring).max()
    p_ring = free_ring.copy()
    held = free_ring < 0.0
    for _ in range(max_rounds):
        at = np.flatnonzero(held)
        h = len(at)
        if h == 0:
            p_ring = free_ring.copy()
            break
        block = np.empty((h, h))
        for j in range(h):
            row = inverse[ring[at[j]]]
            for i in range(h):
                block[i, j] = row[ring[at[i]]]
        nu = -free_ring[at]
        if not cholesky_solve(block, nu):    # not positive definite (rounding): plain LU
            nu = np.linalg.solve(_transposed_block(inverse, ring, at), -free_ring[at])
        if np.any(nu < 0.0):                  # its multiplier pulls: let that cell go
            held[at[nu < 0.0]] = False
            continue
        p_ring = free_ring + _held_response(inverse, ring, at, nu)
        p_ring[at] = 0.0
        more = (p_ring < -1e-12 * scale) & ~held
        if not np.any(more):
            break
        held |= more
    p[ring_at] = p_ring
    return p


@kernel("int32[::1](int32[:, ::1], boolean[:, ::1], int64[::1], int64[::1])")
def nearest_seed_label(labels: np.ndarray, seeds: np.ndarray, rows: np.ndarray,
                       cols: np.ndarray) -> np.ndarray:
    """The ``labels`` of the ``seeds`` cell nearest (Euclidean) to each cell (rows, cols).

    A seed cell is its own nearest.  For any other cell the nearest seed lies on the seeds'
    boundary (a seed with a 4-neighbour that is not one: from a seed whose 4-neighbours are
    all seeds, the step towards the cell is a seed nearer to it), so only those are
    compared.  Ties go to the first in row-major order.  0 without seeds.
    """
    grid_rows, grid_cols = seeds.shape
    edge_r = np.empty(grid_rows * grid_cols, np.int64)
    edge_c = np.empty(grid_rows * grid_cols, np.int64)
    m = 0
    for r in range(grid_rows):
        for c in range(grid_cols):
            if not seeds[r, c]:
                continue
            inner = True
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                rr, cc = r + dr, c + dc
                if 0 <= rr < grid_rows and 0 <= cc < grid_cols and not seeds[rr, cc]:
                    inner = False
            if not inner:
                edge_r[m] = r
                edge_c[m] = c
                m += 1
    out = np.zeros(len(rows), np.int32)
    for k in range(len(rows)):
        r, c = rows[k], cols[k]
        if seeds[r, c]:
            out[k] = labels[r, c]
            continue
        best = np.inf
        for j in range(m):
            d = (edge_r[j] - r) ** 2 + (edge_c[j] - c) ** 2
            if d < best:
                best = d
                out[k] = labels[edge_r[j], edge_c[j]]
    return out
