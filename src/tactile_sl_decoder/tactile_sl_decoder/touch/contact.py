"""Contact state and depth map from per-cell forces and displacements (pad frame).

What a grasping stack reads: whether something touches (with hysteresis, so that noise
near the threshold does not chatter), where (pressure-weighted centroid), how much area
presses, how deep the pad is pushed in (between cells too), and the separate contact
regions with their own force, area and centroid.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from tactile_sl_common.settings import SettingsTable
from tactile_sl_decoder.jit import helper, kernel
from tactile_sl_decoder.touch.support import (
    SupportRegions,
    cholesky_solve,
    nearest_seed_label,
    support_regions,
)


@dataclass
class ContactParams:
    """Thresholds of the contact state."""

    force_on: float = 0.010
    """N: in_contact turns on above this normal force"""
    force_off: float = 0.005
    """N: in_contact turns off below this normal force (hysteresis; <= contact_force_on)"""
    area_fraction: float = 0.0
    """A cell counts into the area above this x its region's peak; 0 = the traction
    solver's choice for the elastomer."""
    core_fraction: float = 0.3
    """A region's centroid from its cells above this x its peak."""
    centroid_smoothing: float = 1.0
    """Cell pitches: the sigma of the Gaussian that smooths the map for the regions' centroids
    (the map's noise is at the scale of a cell, a contact's pressure broader); 0 = none."""
    displacement_noise: float = 3e-6
    """m per axis: weighs the two centroid estimates; the noise of the area's support and
    of max_depth."""
    map_centroid_sigma: float = 6e-5
    """m: uncertainty of the map's centroid (pitch / 8)."""
    depth_upsample: int = 4
    """Depth-map pixels per cell pitch."""
    support_sigmas: float = 2.0
    """A cell is in the area's support above this x its noise."""
    support_edge_snr: float = 5.0
    """A region's area is taken from the support when its edge presses by this x the noise
    (else from the map's threshold)."""
    glyph_spread: float = 0.25
    """Cell pitches, per axis: the rms extent over which a glyph's decoded point averages
    the surface (:func:`max_indentation`); 0 = a point is its cell centre's."""

    def validate(self) -> "ContactParams":
        """Raise ValueError for values outside their ranges (:data:`CONTACT_SETTINGS`)."""
        CONTACT_SETTINGS.check(self, "contact_")
        if self.force_off > self.force_on:
            raise ValueError(f"contact_force_off ({self.force_off}) must not exceed "
                             f"contact_force_on ({self.force_on})")
        if not 0 <= self.core_fraction < 1:
            raise ValueError(f"core_fraction must be in [0, 1), got {self.core_fraction}")
        if not 0 <= self.centroid_smoothing <= 5:
            raise ValueError(f"centroid_smoothing must be in [0, 5] cells, got "
                             f"{self.centroid_smoothing}")
        if self.displacement_noise <= 0 or self.map_centroid_sigma <= 0:
            raise ValueError("displacement_noise and map_centroid_sigma must be > 0")
        if not 0 <= self.area_fraction < 1:
            raise ValueError(f"area_fraction must be in [0, 1), got {self.area_fraction}")
        if not 1 <= self.depth_upsample <= 16:
            raise ValueError(f"depth_upsample must be in 1..16, got {self.depth_upsample}")
        if not (self.support_sigmas > 0 and self.support_edge_snr > 0):
            raise ValueError("support_sigmas and support_edge_snr must be > 0")
        if not 0 <= self.glyph_spread <= 1:
            raise ValueError(f"glyph_spread must be in [0, 1] pitch, got {self.glyph_spread}")
        return self


CONTACT_SETTINGS = SettingsTable(ContactParams, fields=("force_on", "force_off"),
                                 ranges={"force_on": (1e-4, 100.0), "force_off": (1e-4, 100.0)})
"""The decoder node's live ``contact_force_on`` and ``contact_force_off`` parameters."""


@dataclass
class ContactState:
    """The contract's Contact message, plus regions (all SI, pad frame)."""

    in_contact: bool = False
    area: float = 0.0
    centroid: tuple[float, float, float] = (0.0, 0.0, 0.0)
    max_depth: float = 0.0
    normal_force: float = 0.0
    shear_force: tuple[float, float, float] = (0.0, 0.0, 0.0)
    peak_pressure: float = 0.0
    cells_in_contact: int = 0
    region_force: list[float] = field(default_factory=list)
    region_area: list[float] = field(default_factory=list)
    region_centroid: list[tuple[float, float, float]] = field(default_factory=list)


_DR, _DC = (a.ravel() for a in np.mgrid[-1:2, -1:2])
# z = a + b x + c y + d x^2 + e y^2 + g x y on the 3x3 stencil (x along columns, in cells)
_DESIGN = np.column_stack([np.ones(9), _DC, _DR, _DC ** 2, _DR ** 2, _DC * _DR]).astype(float)
_RING = np.flatnonzero((_DR != 0) | (_DC != 0))
# the centre value of the quadratic through the 8 neighbours, and the standard deviation of a
# cell's difference from it per unit of i.i.d. noise
_FROM_RING = np.linalg.pinv(_DESIGN[_RING])[0]
_FROM_RING_SPREAD = float(np.sqrt(1.0 + _FROM_RING @ _FROM_RING))
# standard deviation of a curvature 2d (or 2e) of the full-stencil fit per unit of noise
_CURVATURE_SPREAD = float(2.0 * np.sqrt(np.linalg.inv(_DESIGN.T @ _DESIGN)[3, 3]))
_CROSS_CHECK = np.array([[0, 2], [0, -2], [2, 0], [-2, 0]])   # (row, col): two cells away
OUTLIER_SIGMAS = 5.0    # a cell this far (x its spread) from its neighbours' quadratic: dropped
FIT_SIGMAS = 3.0        # a neighbourhood fits a quadratic when its residual RMS is below this
CURVATURE_SIGMAS = 3.0  # the peak is moved between cells along curvatures beyond this
CANDIDATES = 16         # neighbourhoods of the deepest cells fitted


def max_indentation(indent: np.ndarray, noise: float = 3e-6, spread: float = 0.0) -> float:
    """Largest indentation of a (rows, cols) grid (NaN = not decoded), between cells too.

    ``noise``: the displacement noise per cell (m).  Robust to the few cells a decoder gets
    wrong where the surface is steep (the rim of a flat punch: up to 90 um off):

    1. a cell farther than ``OUTLIER_SIGMAS`` x its spread both from the quadratic through
       its 8 neighbours (the surface's second-order Taylor expansion) and from their median
       is left out: a lone cell off its surroundings (a sphere's apex fits the quadratic, a
       small flat face ringed by a steep rim sits at its neighbours' median);
    2. the 3x3 neighbourhoods (of the cells left) of the ``CANDIDATES`` deepest cells are
       fitted with z = a + b x + c y + d x^2 + e y^2 + g x y by least squares (7 cells or
       more); a candidate's value is the fit's centre value a where the residual RMS is
       within ``FIT_SIGMAS`` x the noise (a smooth surface: a sphere's apex, a punch's face,
       a cylinder's crest), else its own (a steep or broken neighbourhood); the largest wins;
    3. a smooth winner's peak moves from its centre along the directions of the fit's
       curvature that stand out of the noise (``CURVATURE_SIGMAS``), to the stationary point
       when it lies within one cell and the fit predicts the cells two cells away along the
       rows and columns (two of them at least, each within 4 x noise + half the predicted
       drop: a step that three cells cannot tell from a dome fails it).  A spherical tip's
       surface is exactly such a paraboloid inside the contact; a flat face has no
       curvature to move along;
    4. that peak is deepened by ``spread``^2 / 2 times those curvatures (in cells^-2): a
       decoded point is not its cell centre's surface point but the surface averaged over
       the glyph as the cameras see it, and the average of a dome of curvature k over a
       spread s lies s^2 k / 2 below its centre (the mean of g(x) over x of variance s^2
       is g(0) + g''(0) s^2 / 2 to second order: A. Papoulis and S. U. Pillai, *Probability,
       Random Variables and Stochastic Processes*, 4th ed., sec. 5-4).  ``spread`` is in
       cells, rms per axis (0: none).  Measured on the simulator's indenter scenes, the
       normal displacement error of the cells in contact regresses on the true field's
       Laplacian with a spread of 0.20-0.36 pitch (median 0.26; docs/touch.md): more than
       the ink's own 0.13 (a disc of 0.22 pitch^2), probably because the two cameras see
       the curved glyph from either side, so its foreshortening moves their centroids apart.

    Never negative.  No candidate left: the deepest cell kept around them (or the deepest
    cell); no neighbourhood of 7 cells: the deepest candidate.  Compiled (numba): only the
    cells around the deepest ones are looked at.
    """
    grid = np.ascontiguousarray(indent, dtype=np.float64)
    if grid.size == 0:
        return 0.0
    return float(_max_indentation(grid, float(noise), CANDIDATES, OUTLIER_SIGMAS, FIT_SIGMAS,
                                  CURVATURE_SIGMAS, float(spread)))


@helper
def _kept(z: np.ndarray, r: int, c: int, limit: float, memo: np.ndarray) -> bool:
    """:func:`_kept_cell`, each cell worked out once (``memo``: -1 not yet, 0 no, 1 yes).

    The neighbourhoods of the deepest cells overlap: most cells are asked about many times.
    """
    rows, cols = z.shape
    if r < 0 or c < 0 or r >= rows or c >= cols:
        return False
    if memo[r, c] < 0:
        memo[r, c] = 1 if _kept_cell(z, r, c, limit) else 0
    return memo[r, c] == 1


@helper
def _kept_cell(z: np.ndarray, r: int, c: int, limit: float) -> bool:
    """Decoded, and near the quadratic through its 8 neighbours or near their median."""
    rows, cols = z.shape
    if not np.isfinite(z[r, c]):
        return False
    if r < 1 or c < 1 or r + 1 >= rows or c + 1 >= cols:
        return True                         # not all 8 neighbours: not tested
    pred = 0.0
    for j in range(8):
        v = z[r + _DR[_RING[j]], c + _DC[_RING[j]]]
        if not np.isfinite(v):
            return True
        pred += _FROM_RING[j] * v
    if abs(z[r, c] - pred) <= limit:
        return True
    ring = np.empty(8)                 # (allocated only here: the rare cell off the fit)
    for j in range(8):
        ring[j] = z[r + _DR[_RING[j]], c + _DC[_RING[j]]]
    ring.sort()                        # and off the neighbours' median: a lone cell
    return abs(z[r, c] - 0.5 * (ring[3] + ring[4])) <= limit


@helper
def _deepest(z: np.ndarray, count: int) -> tuple[np.ndarray, float]:
    """The ``count`` deepest decoded cells and the deepest value.

    Flat indices, deepest first (-1: fewer cells), ties in their order; -inf: none decoded.
    """
    rows, cols = z.shape
    top = np.full(count, -1, np.int64)
    topv = np.full(count, -np.inf)
    best = -np.inf
    for i in range(rows * cols):
        v = z[i // cols, i % cols]
        if not np.isfinite(v):
            continue
        best = max(best, v)
        if v > topv[count - 1]:
            k = count - 1
            while k > 0 and topv[k - 1] < v:
                topv[k] = topv[k - 1]
                top[k] = top[k - 1]
                k -= 1
            topv[k] = v
            top[k] = i
    return top, best


@helper
def _fit(z: np.ndarray, r: int, c: int, limit: float, coef: np.ndarray,
         normal: np.ndarray, memo: np.ndarray) -> float:
    """Quadratic through the kept cells of (r, c)'s 3x3 into ``coef``; its residual RMS.

    -1 when fewer than 7 cells are kept (or the fit is singular).  ``normal``: a 6x6
    scratch array for the normal equations.
    """
    normal[:, :] = 0.0
    coef[:] = 0.0
    count = 0
    for j in range(9):
        rr, cc = r + _DR[j], c + _DC[j]
        if not _kept(z, rr, cc, limit, memo):
            continue
        count += 1
        for a in range(6):
            coef[a] += _DESIGN[j, a] * z[rr, cc]
            for b in range(6):
                normal[a, b] += _DESIGN[j, a] * _DESIGN[j, b]
    if count < 7 or not cholesky_solve(normal, coef):
        return -1.0
    ss = 0.0
    for j in range(9):
        rr, cc = r + _DR[j], c + _DC[j]
        if _kept(z, rr, cc, limit, memo):
            f = 0.0
            for a in range(6):
                f += _DESIGN[j, a] * coef[a]
            ss += (z[rr, cc] - f) ** 2
    return np.sqrt(ss / max(count - 6, 1))


@helper
def _gain(cf: np.ndarray, threshold: float) -> tuple[float, float, float, float]:
    """Step (x, y) to the stationary point along the curvatures below ``threshold``.

    Returns the step, the rise to that point and the sum of those curvatures (the glyph
    average's correction); the eigen-decomposition of the Hessian [[2d, g], [g, 2e]] in
    closed form.
    """
    h11, h22, h12 = 2.0 * cf[3], 2.0 * cf[4], cf[5]
    mean = 0.5 * (h11 + h22)
    rad = np.sqrt(0.25 * (h11 - h22) ** 2 + h12 * h12)
    theta = 0.5 * np.arctan2(2.0 * h12, h11 - h22)      # the larger eigenvalue's axis
    sx, sy, gain, bent = 0.0, 0.0, 0.0, 0.0
    for sign in (-1.0, 1.0):
        lam = mean + sign * rad
        if lam >= threshold:
            continue
        bent += lam
        if sign > 0:
            vx, vy = np.cos(theta), np.sin(theta)
        else:
            vx, vy = -np.sin(theta), np.cos(theta)
        slope = cf[1] * vx + cf[2] * vy
        sx += (-slope / lam) * vx
        sy += (-slope / lam) * vy
        gain += -slope * slope / (2.0 * lam)
    return sx, sy, gain, bent


@helper
def _predicts_cross(z: np.ndarray, r0: int, c0: int, cf: np.ndarray, limit: float,
                    noise: float, memo: np.ndarray) -> bool:
    """The fit predicts at least two kept cells two cells away along rows and columns."""
    checked = 0
    for k in range(4):
        dr, dc = _CROSS_CHECK[k, 0], _CROSS_CHECK[k, 1]
        if _kept(z, r0 + dr, c0 + dc, limit, memo):
            checked += 1
            q = (cf[0] + cf[1] * dc + cf[2] * dr + cf[3] * dc * dc + cf[4] * dr * dr
                 + cf[5] * dc * dr)
            if abs(z[r0 + dr, c0 + dc] - q) > 4.0 * noise + 0.5 * abs(cf[0] - q):
                return False
    return checked >= 2


@kernel("float64(float64[:, ::1], float64, int64, float64, float64, float64, float64)")
def _max_indentation(z: np.ndarray, noise: float, candidates: int, outlier_sigmas: float,
                     fit_sigmas: float, curvature_sigmas: float, spread: float) -> float:
    """The steps of :func:`max_indentation` (see there)."""
    cols = z.shape[1]
    limit = outlier_sigmas * _FROM_RING_SPREAD * noise
    top, best_valid = _deepest(z, candidates)
    if best_valid == -np.inf:
        return 0.0
    kept_best = -np.inf          # around the candidates
    deepest_kept = -np.inf       # of the candidates
    best = -np.inf
    best_smooth = False
    best_cell = -1
    coef = np.zeros(6)
    best_coef = np.zeros(6)
    normal = np.zeros((6, 6))
    memo = np.full(z.shape, -1, np.int8)
    for m in range(candidates):
        i = top[m]
        if i < 0:
            break
        r, c = i // cols, i % cols
        for dr in range(-2, 3):
            for dc in range(-2, 3):
                if _kept(z, r + dr, c + dc, limit, memo):
                    kept_best = max(kept_best, z[r + dr, c + dc])
        if not _kept(z, r, c, limit, memo):
            continue
        deepest_kept = max(deepest_kept, z[r, c])
        rms = _fit(z, r, c, limit, coef, normal, memo)
        if rms < 0.0:
            continue
        smooth = rms <= fit_sigmas * noise
        value = coef[0] if smooth else z[r, c]
        if best_cell < 0 or value > best:
            best, best_smooth, best_cell = value, smooth, i
            best_coef[:] = coef
    if kept_best == -np.inf:
        return max(best_valid, 0.0)
    if deepest_kept == -np.inf:
        return max(kept_best, 0.0)
    if best_cell < 0:
        return max(deepest_kept, 0.0)
    if best_smooth:
        sx, sy, gain, bent = _gain(best_coef, -curvature_sigmas * _CURVATURE_SPREAD * noise)
        if (gain > 0.0 and abs(sx) <= 1.0 and abs(sy) <= 1.0
                and _predicts_cross(z, best_cell // cols, best_cell % cols, best_coef, limit,
                                    noise, memo)):
            best += gain - 0.5 * spread * spread * bent
    return max(best, 0.0)


def contact_hysteresis(normal_force: float, was_in_contact: bool,
                       params: ContactParams) -> bool:
    """``in_contact`` of a frame from its normal force (N) and the last frame's.

    Above ``force_on``, or above ``force_off`` while the last frame was in contact: noise
    near one threshold cannot chatter.
    """
    return normal_force > (params.force_off if was_in_contact else params.force_on)


def contact_state(rest_xy: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                  forces: np.ndarray, wrench: np.ndarray, shape: tuple[int, int], pitch: float,
                  indent_grid: np.ndarray, was_in_contact: bool, params: ContactParams,
                  moment_noise: tuple[float, float] = (0.0, 0.0),
                  support: tuple[np.ndarray, np.ndarray] | None = None,
                  map_noise: np.ndarray | None = None,
                  centroid_noise: np.ndarray | None = None,
                  fit_centroid: tuple[np.ndarray, np.ndarray] | None = None) -> ContactState:
    """Contact state from per-cell forces (N) at rest positions (m) and the resultant.

    Normal and shear force come from the resultant.  The regions come from the per-cell
    map: a region is a set of 8-connected pressing cells with at least one cell pressing by
    more than ``area_fraction`` of the map's peak (smaller ripples of the map are not
    contacts).  With ``support`` (the constrained pressure and its noise, N, per reference
    cell, :mod:`.support`) a map region holding regions of the traction's support that
    locate their edge (``support_edge_snr``) is split among them (each map cell to the
    nearest: two contacts whose skirts join in the map stay two), and each takes the area
    of its support region.  Otherwise a region's area is that of the map's cells above
    ``area_fraction`` of its peak (the map is smooth over about a cell, so its low skirt
    lies outside the contact; the stage passes the fraction its traction solver calibrated
    on Hertz discs for the elastomer, see
    :meth:`~tactile_sl_decoder.touch.traction.TractionSolver._area_fraction`).
    ``max_depth``: :func:`max_indentation` with ``displacement_noise``.

    The centroid has two estimates: the resultant's, (M_y, -M_x) / P (exact for tractions
    at z = 0 since M = sum r x f, but its noise grows with the lever arms of the whole
    field: ``moment_noise`` is ||row|| of the M_x, M_y functionals, so the standard
    deviation is ``displacement_noise`` x that / P), and the map's (force-weighted region
    centroids, each from the region's cells above ``core_fraction`` of its peak in the map
    smoothed by ``centroid_smoothing``, :func:`smoothed_map`: local, uncertain to about
    ``map_centroid_sigma``).  They are combined per axis by inverse
    variance (the minimum-variance unbiased combination of two independent estimates).

    ``map_noise`` (N,): the standard deviation of each cell's map force (N), propagated
    from the cells' expected displacement errors
    (:meth:`~tactile_sl_decoder.touch.weights.CellWeights.propagated`).  With it a region
    whose force is less than ``RIPPLE_SIGMAS`` x its noise (sqrt(sum s_i^2): independent
    cells) is a ripple of the noise, not a contact, and dropped (a frame whose every region
    is one takes the resultant's centroid).  ``centroid_noise`` (N,): the part of each
    cell's map noise beyond that of ``displacement_noise``; with it a region's map centroid
    is uncertain by ``map_centroid_sigma`` and, in quadrature, its core's RMS radius times
    the peak cell's noise-to-force ratio (the core, the cells above ``core_fraction`` of
    the peak, is chosen by a peak the noise moves), so that a faint contact under harsh
    light leans on the resultant's centroid.
    """
    press = np.maximum(-forces[:, 2], 0.0)
    normal = max(-float(wrench[2]), 0.0)
    cell_area = pitch * pitch
    state = ContactState(normal_force=normal,
                         shear_force=(float(wrench[0]), float(wrench[1]), 0.0),
                         max_depth=max_indentation(indent_grid, params.displacement_noise,
                                                   params.glyph_spread))
    state.in_contact = contact_hysteresis(normal, was_in_contact, params)
    pressing = press > 0.0
    if normal <= 0.0 or not pressing.any():
        return state
    smooth = smoothed_map(-forces[:, 2], rows, cols, shape, params.centroid_smoothing)
    state.peak_pressure = float(press.max() / cell_area)
    grid = np.zeros(shape, np.uint8)
    grid[rows[pressing], cols[pressing]] = 1
    count, labels = cv2.connectedComponents(grid, connectivity=8)
    region = labels[rows, cols]
    regions = []
    spread = []            # per region: the noise variance of its map centroid (m^2)
    level = params.area_fraction * float(press.max())
    found = _support(support, rows, cols, shape, params)
    for k in range(1, count):
        sel = pressing & (region == k)
        w = press[sel]
        parts = [] if found is None else _support_parts(found, labels, k, rows[sel], cols[sel])
        if found is not None and parts:   # the support's regions in this one, with their cells
            for part, mine in parts:
                wp = w[mine]
                core = _core(smooth[sel][mine], wp, params.core_fraction)
                c = (core[:, None] * rest_xy[sel][mine]).sum(axis=0) / core.sum()
                noise = None if map_noise is None else map_noise[sel][mine]
                if noise is not None and _ripple(wp, noise):
                    continue
                regions.append((float(wp.sum()), float(found.area_cells[part]) * cell_area,
                                (float(c[0]), float(c[1]), 0.0), int(found.cells[part])))
                spread.append(_centroid_variance(
                    core, rest_xy[sel][mine], c,
                    None if centroid_noise is None else centroid_noise[sel][mine]))
            continue
        inside = int((w > level).sum())
        if inside == 0:          # a ripple of the map, not a contact
            continue
        noise = None if map_noise is None else map_noise[sel]
        if noise is not None and _ripple(w, noise):
            continue             # ... or of the noise
        core = _core(smooth[sel], w, params.core_fraction)
        c = (core[:, None] * rest_xy[sel]).sum(axis=0) / core.sum()
        regions.append((float(w.sum()), inside * cell_area, (float(c[0]), float(c[1]), 0.0),
                        inside))
        spread.append(_centroid_variance(
            core, rest_xy[sel], c, None if centroid_noise is None else centroid_noise[sel]))
    from_wrench = np.array([float(wrench[4]) / normal, -float(wrench[3]) / normal])
    var_wrench = (params.displacement_noise * np.array([moment_noise[1], moment_noise[0]])
                  / normal) ** 2
    w_wrench = 1.0 / np.maximum(var_wrench, 1e-30)
    estimates = [(w_wrench, from_wrench)]
    if fit_centroid is not None:    # the pressure fitted on the contact's cells
        estimates.append((1.0 / np.maximum(fit_centroid[1], 1e-30), fit_centroid[0]))
    if not regions:          # every region a ripple of the noise: the resultant's centroid
        state.centroid = _combined(estimates)
        return state
    order = sorted(range(len(regions)), key=lambda i: -regions[i][0])   # stable, as sort
    regions = [regions[i] for i in order]
    spread = [spread[i] for i in order]
    state.region_force = [r[0] for r in regions]
    state.region_area = [r[1] for r in regions]
    state.region_centroid = [r[2] for r in regions]
    state.area = float(sum(state.region_area))
    state.cells_in_contact = int(sum(r[3] for r in regions))
    total = sum(state.region_force)
    from_map = np.array([sum(f * c[i] for f, c in zip(state.region_force,
                                                      state.region_centroid)) / total
                         for i in (0, 1)])
    w_map = 1.0 / (params.map_centroid_sigma ** 2
                   + sum((f / total) ** 2 * v for f, v in zip(state.region_force, spread)))
    state.centroid = _combined([(np.full(2, w_map), from_map)] + estimates)
    return state


def smoothed_map(pressure: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                 shape: tuple[int, int], sigma: float) -> np.ndarray:
    """Per cell (N,), the ``pressure`` map smoothed by a Gaussian of ``sigma`` cells.

    The strongly regularised map resolves about a cell, and what noise it keeps is at that
    scale, while a contact presses over several cells: a region's centroid from the
    smoothed map keeps the contact's (a symmetric kernel moves no centroid) with a fraction
    of the noise (a 0.05 N Hertz load of 4.5 mm on the half-space, eight draws: 0.096 ->
    0.041 mm RMS).  Cells that were not decoded count as pressing by nothing (no mass is
    invented near a gap or the border: a normalised convolution would inflate the last
    cells before one and pull the centroid towards it).  ``sigma`` 0 returns ``pressure``.
    """
    if sigma <= 0:
        return pressure
    size = 2 * int(np.ceil(3.0 * sigma)) + 1
    values = np.zeros(shape)
    values[rows, cols] = pressure
    blurred = cv2.GaussianBlur(values, (size, size), sigma, borderType=cv2.BORDER_CONSTANT)
    out: np.ndarray = blurred[rows, cols]
    return out


def _core(smooth: np.ndarray, press: np.ndarray, fraction: float) -> np.ndarray:
    """A region's centroid weights: its smoothed pressure above ``fraction`` of its peak.

    Its own ``press`` where the smoothed map does not press (a thin region among pulling
    cells); 0 below the fraction.
    """
    pressure = smooth if smooth.max() > 0.0 else press
    return np.where(pressure > fraction * pressure.max(), pressure, 0.0)


def _combined(estimates: list[tuple[np.ndarray, np.ndarray]]) -> tuple[float, float, float]:
    """Per axis, the inverse-variance combination of (weight (2,), centroid (2,)) estimates."""
    if len(estimates) == 1:
        return (float(estimates[0][1][0]), float(estimates[0][1][1]), 0.0)
    weight = sum(w for w, _ in estimates)
    c = sum(w * c for w, c in estimates) / weight
    return (float(c[0]), float(c[1]), 0.0)


RIPPLE_SIGMAS = 8.0
"""A map region whose force is below this x its noise is dropped."""


def _ripple(force: np.ndarray, noise: np.ndarray) -> bool:
    """The region's force (per cell, N) is within ``RIPPLE_SIGMAS`` x its ``noise``."""
    return bool(_within_noise(force.sum(), np.sum(noise ** 2)))


def _within_noise(force: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """Total force(s) (N) within ``RIPPLE_SIGMAS`` x sqrt(``variance``): ripples."""
    return force <= RIPPLE_SIGMAS * np.sqrt(variance)


def without_ripples(core: np.ndarray, press: np.ndarray, noise: np.ndarray, rows: np.ndarray,
                    cols: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``core`` (N,) bool without its 8-connected parts that are ripples of the noise.

    ``press`` (N,) N each cell's pressing force and ``noise`` (N,) N its standard deviation
    (the map's, propagated from the cells' expected errors).  A part whose force is within
    ``RIPPLE_SIGMAS`` x sqrt(sum s_i^2) (independent cells) is dropped, as the contact
    state drops such map regions; if every part is one, the part pressing hardest is kept
    (the caller asked for a core).  Under harsh light a faint contact's map is a plateau of
    noise, and the cells above a fraction of its peak are scattered over the pad: fitted as
    pressing (:mod:`.consistent`) they add their noise to the contact's force and centroid.
    """
    if not core.any():
        return core
    grid = np.zeros(shape, np.uint8)
    grid[rows[core], cols[core]] = 1
    count, labels = cv2.connectedComponents(grid, connectivity=8)
    part = labels[rows, cols]
    force = np.bincount(part[core], np.maximum(press[core], 0.0), count)
    var = np.bincount(part[core], noise[core] ** 2, count)
    keep = ~_within_noise(force, var)
    keep[0] = False
    if not keep.any():
        keep[int(np.argmax(np.where(np.arange(count) > 0, force, -np.inf)))] = True
    out: np.ndarray = core & keep[part]
    return out


def _centroid_variance(core: np.ndarray, xy: np.ndarray, c: np.ndarray,
                       noise: np.ndarray | None) -> float:
    """Noise variance (m^2 per axis) of a region's map centroid; 0 without ``noise``.

    The core's RMS radius about ``c`` times the peak's ``noise``-to-force ratio, squared.
    """
    if noise is None:
        return 0.0
    peak = int(np.argmax(core))
    inside = core > 0
    radius2 = float(np.mean(np.sum((xy[inside] - c[:2]) ** 2, axis=1)))
    return radius2 * float(noise[peak] / core[peak]) ** 2


def _support(support: tuple[np.ndarray, np.ndarray] | None, rows: np.ndarray,
             cols: np.ndarray, shape: tuple[int, int], params: ContactParams
             ) -> SupportRegions | None:
    """The support's regions on the cell grid (None without ``support``)."""
    if support is None:
        return None
    pressure, noise = support
    p = np.zeros(shape)
    sig = np.full(shape, np.inf)
    p[rows, cols] = pressure
    sig[rows, cols] = noise
    found = support_regions(p, sig, params.support_sigmas)
    found.edge_snr[found.edge_snr < params.support_edge_snr] = 0.0     # not used
    return found


def _support_parts(found: SupportRegions, labels: np.ndarray, k: int, rows: np.ndarray,
                   cols: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """The support regions of map region ``k`` that locate their edge, and its cells' share.

    A support region belongs to the map region holding its largest pressure.  Each of the
    map region's cells (``rows``, ``cols``) goes to the nearest cell of those regions (two
    contacts the map's skirt joins are told apart).  Empty when there are none.
    """
    ids = [int(j) for j in np.flatnonzero(found.edge_snr > 0)
           if labels.flat[found.peak[j]] == k]
    if not ids:
        return []
    if len(ids) == 1:                      # one contact in this map region: all its cells
        return [(ids[0], np.ones(len(rows), bool))]
    seeds = np.isin(found.labels, ids) & found.support
    owner = nearest_seed_label(found.labels, seeds, np.ascontiguousarray(rows, np.int64),
                               np.ascontiguousarray(cols, np.int64))
    return [(j, owner == j) for j in ids if np.any(owner == j)]


@dataclass(frozen=True)
class DepthGrid:
    """Where the depth map's pixels lie: pixel (i, j) is at (x0 + j res, y0 + i res, 0)."""

    x0: float
    y0: float
    resolution: float
    width: int
    height: int


def depth_grid(shape: tuple[int, int], pitch: float, upsample: int,
               mirrored: bool = False) -> DepthGrid:
    """The depth map covers the pattern's cell centres, ``upsample`` pixels per pitch."""
    rows, cols = shape
    res = pitch / upsample
    width = (cols - 1) * upsample + 1
    height = (rows - 1) * upsample + 1
    return DepthGrid(-(cols - 1) / 2.0 * pitch, -(rows - 1) / 2.0 * pitch, res, width, height)


class DepthMapper:
    """Indentation (m, > 0 pressed in) on the depth grid, bilinear between cell centres.

    ``indent`` is the (rows, cols) cell grid, NaN where a cell was not decoded; a pixel is
    NaN when any cell it interpolates between (with a non-zero weight) is missing, so cell
    centres keep their value next to a gap.  With ``mirrored`` the columns are flipped so
    that image x always runs along the pad frame's x.  The sampling maps are built once
    (cv2.remap: bilinear weights in 1/32 steps, exact for 1, 2, 4, 8, 16 pixels per pitch).
    """

    def __init__(self, shape: tuple[int, int], upsample: int, mirrored: bool = False) -> None:
        rows, cols = shape
        self.mirrored = bool(mirrored)
        ys = np.arange((rows - 1) * upsample + 1, dtype=np.float32) / upsample
        xs = np.arange((cols - 1) * upsample + 1, dtype=np.float32) / upsample
        self._map_x, self._map_y = np.meshgrid(xs, ys)

    def __call__(self, indent: np.ndarray) -> np.ndarray:
        grid = indent[:, ::-1] if self.mirrored else indent
        valid = np.isfinite(grid)
        both = np.dstack([np.where(valid, grid, 0.0), valid]).astype(np.float32)
        out = cv2.remap(both, self._map_x, self._map_y, cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)
        depth = out[..., 0].copy()
        depth[out[..., 1] < 1.0 - 1e-6] = np.nan
        return depth


def depth_map(indent: np.ndarray, upsample: int, mirrored: bool = False) -> np.ndarray:
    """One-off :class:`DepthMapper` call (tests, tools)."""
    return DepthMapper(indent.shape, upsample, mirrored)(indent)
