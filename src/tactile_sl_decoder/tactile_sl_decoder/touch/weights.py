"""Per-cell weights: each cell's expected error, and a displacement field cleaned by it.

Under harsh light (shadows, vignetted corners, dust, low light, MJPEG) the stereo error of a
cell is far from uniform: on the harsh-light scenes (bags/light_scenes.yaml) the median cell
is off by 6 um but one in a hundred by 50-100 um, and always the same cells (the dark ones).
A few such cells move the unweighted resultant and the pressure map's centroid.  Three
steps, vectorised numpy over the reference's cells:

1. **Expected error** (:func:`expected_error`, once per reference).  The untouched pad is
   smooth, so the roughness of the reference is its noise: each cell's position is compared
   with a quadratic fitted to its neighbours (leave-one-out, :func:`local_fit`), the squared
   residuals are averaged over the 3 x 3 cells around it (noise varies smoothly with the
   light) and divided by 1 + the fit's own variance factor.  A dented reference (pressed
   while taken) is smooth too and costs nothing; the floor ``min_error`` keeps a cell that
   happens to sit on its neighbours' surface from being trusted without limit.  A
   displacement is a difference of two measurements (the frame's and the reference's
   average over ``reference_frames``), so its expected error is sigma sqrt(1 + 1/frames).
   With several reference frames sigma is their scatter instead (:func:`scatter_error`,
   each cell's variance over the frames, averaged over the same 3 x 3 cells): the mean of
   several frames is smoother than any one of them, and its roughness would give sigma /
   sqrt(frames) (under harsh light five frames made every loaded frame worse, 7.0-8.5 um
   against 3.7-5.1 um with one, until sigma came from the scatter: 3.6-4.8 um).

2. **Robust cleaning** (:meth:`CellWeights.clean`, per frame).  The cells whose expected
   error exceeds ``noisy_factor`` x the floor (none on a clean pad: clean frames are taken
   as measured, byte for byte) are predicted from their neighbours: a quadratic fitted by
   weighted least squares with weights 1 / sigma^2 (inverse variance: the best linear
   unbiased estimate, Aitken 1935, Proc. R. Soc. Edinburgh 55, "On least squares and linear
   combination of observations"), leave-one-out.  The prediction is linear in the
   neighbours' values, so it is prepared once per reference as a stencil of 24 weights per
   cell, and a frame costs one gather and one weighted sum.  The cell's value becomes the
   inverse-variance combination of its own measurement and that prediction, the
   prediction's variance being the fit's plus ``model_error``^2 + (``model_error_relative``
   x the prediction)^2 (how far a quadratic departs from a real indentation over 5 x 5
   cells: a floor, and a share of the displacement, largest at a deep contact's edge).
   A measurement whose standardised departure from the prediction,
   t = |u - u_fit| / sqrt(sigma^2 + var_fit), exceeds ``huber_k`` gets the Huber weight
   k / |t| (Huber, Robust Statistics, Wiley 1981, sec. 7.8: the M-estimate's weight
   psi(t) / t), so a gross stereo error does not survive even where its expected error was
   underestimated.

3. **Propagated noise** (:meth:`CellWeights.propagated`).  The errors left after cleaning
   give the standard deviation of any linear functional of the field, sqrt(sum R_j^2
   sigma_j^2): the resultant's moments (the contact state weighs the resultant's centroid
   against the map's by it, never below the clean ``displacement_noise``) and each cell's
   map force (a map region whose force is within 8 sigma of its noise is a ripple of the
   noise, not a contact: :func:`~tactile_sl_decoder.touch.contact.contact_state`).

The traction inversion (:mod:`.traction`) then runs on the cleaned field: its resultant,
map, contact area, centroid and indentation all come from it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from tactile_sl_common.settings import SettingsTable

RADIUS = 2
"""Neighbours within this many cells along rows and columns (a 5 x 5 window)."""


@dataclass
class WeightParams:
    """Settings of the per-cell weights (see the module docstring)."""

    enabled: bool = True
    """Clean each frame's displacement by the cells' expected errors; False: every cell
    taken as measured (the behaviour before issue 25)."""
    min_error: float = 1.5e-6
    """m: the floor of a cell's expected position error (per axis)."""
    noisy_factor: float = 4.0
    """Cells whose expected displacement error (largest axis) exceeds this x
    ``min_error`` are cleaned; the others are taken as measured."""
    model_error: float = 2e-6
    """m: how far the 5 x 5 quadratic may depart from a real displacement field ..."""
    model_error_relative: float = 0.03
    """... plus this fraction of the predicted displacement (in quadrature): the departure
    grows with the indentation's depth (steepest at a contact's edge)."""
    huber_k: float = 2.5
    """Standardised departure beyond which a measurement is down-weighted (Huber's k)."""
    fit_normal: bool = True
    """On a pad where most cells are noisy, report the normal displacement the contact's
    pressure explains (:mod:`.consistent`; ~1 ms a frame there); False: as cleaned."""

    def validate(self) -> "WeightParams":
        """Raise ValueError for values outside their ranges (:data:`WEIGHT_SETTINGS`)."""
        WEIGHT_SETTINGS.check(self, "touch_weights.")
        return self


WEIGHT_SETTINGS = SettingsTable(
    WeightParams, ranges={"min_error": (1e-9, 1e-3), "model_error": (1e-9, 1e-3),
                          "noisy_factor": (1.0, 1e3), "model_error_relative": (0.0, 0.99),
                          "huber_k": (0.5, 100.0)},
    read_only=("enabled", "min_error", "noisy_factor", "model_error", "model_error_relative",
               "huber_k", "fit_normal"))
"""The decoder node's ``touch_weights.*`` parameters: read at start (the expected errors
are a reference's, prepared in the background), so refused live."""


def _basis() -> tuple[np.ndarray, np.ndarray]:
    """The window's offsets without the centre (K, 2) and their quadratic basis (K, 6)."""
    d = np.arange(-RADIUS, RADIUS + 1, dtype=np.float64)
    dr, dc = (a.ravel() for a in np.meshgrid(d, d, indexing="ij"))
    keep = (dr != 0) | (dc != 0)
    dr, dc = dr[keep], dc[keep]
    phi = np.column_stack([np.ones_like(dr), dc, dr, dc * dc, dc * dr, dr * dr])
    return np.column_stack([dr, dc]).astype(np.int64), phi


_OFFSETS, _PHI = _basis()
_OUTER = np.einsum("ka,kb->kab", _PHI, _PHI).reshape(len(_PHI), 36)


def _neighbours(grid: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Values of ``grid`` (H, W, ...) at each cell's window offsets: (N, K, ...), 0 outside."""
    h, w = grid.shape[:2]
    padded = np.zeros((h + 2 * RADIUS, w + 2 * RADIUS) + grid.shape[2:], grid.dtype)
    padded[RADIUS:RADIUS + h, RADIUS:RADIUS + w] = grid
    r = rows[:, None] + _OFFSETS[None, :, 0] + RADIUS
    c = cols[:, None] + _OFFSETS[None, :, 1] + RADIUS
    out: np.ndarray = padded[r, c]
    return out


def local_fit(values: np.ndarray, weights: np.ndarray, rows: np.ndarray, cols: np.ndarray,
              shape: tuple[int, int], at: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-out weighted quadratic fit of each cell's neighbours, evaluated at the cell.

    ``values`` (N, C) at the cells (``rows``, ``cols``) of a grid of ``shape``; ``weights``
    (N,) >= 0 (0: not used).  For each cell of ``at`` (indices into the N cells; all when
    None) the quadratic a + b dc + c dr + d dc^2 + e dc dr + f dr^2 is fitted to the cells
    within :data:`RADIUS` (itself left out) by weighted least squares, per column of
    ``values``.  Returns (prediction (M, C), variance factor (M,)): the prediction's
    variance is e0^T (Phi^T W Phi)^-1 e0 for weights W = 1 / sigma^2; a cell with fewer than
    9 usable neighbours gets NaN and inf.
    """
    values = np.asarray(values, np.float64)
    if values.ndim == 1:
        values = values[:, None]
    rows = np.asarray(rows, np.int64)
    cols = np.asarray(cols, np.int64)
    idx = np.arange(len(rows)) if at is None else np.asarray(at, np.int64)
    nb, coef, factor = _stencils(rows, cols, shape, np.asarray(weights, np.float64), idx)
    pred = np.einsum("mk,mkc->mc", coef, values[nb])
    pred[~np.isfinite(factor)] = np.nan
    return pred, factor


def expected_error(rows: np.ndarray, cols: np.ndarray, rest: np.ndarray, nominal: np.ndarray,
                   shape: tuple[int, int], min_error: float) -> np.ndarray:
    """Expected position error (N, 3) m of each reference cell, from the reference's roughness.

    ``rest`` (N, 3) the reference positions and ``nominal`` (N, 3) the nominal rest positions
    (pad frame).  See the module docstring (step 1); floored at ``min_error``.
    """
    rows = np.asarray(rows, np.int64)
    cols = np.asarray(cols, np.int64)
    offset = np.asarray(rest, np.float64) - np.asarray(nominal, np.float64)
    pred, factor = local_fit(offset, np.ones(len(rows)), rows, cols, shape)
    resid2 = (offset - pred) ** 2 / (1.0 + factor[:, None])
    return np.maximum(np.sqrt(_around(resid2, rows, cols, shape)), min_error)


def scatter_error(rows: np.ndarray, cols: np.ndarray, variance: np.ndarray,
                  shape: tuple[int, int], min_error: float) -> np.ndarray:
    """Expected position error (N, 3) m of one frame, from the reference frames' scatter.

    ``variance`` (N, 3) m^2: each cell's sample variance over the frames averaged into the
    reference (pad frame; NaN where a cell was seen once), averaged over the 3 x 3 cells
    around it like the roughness (:func:`expected_error`); floored at ``min_error``.  With
    several reference frames this is the frame's noise itself; the roughness of their mean
    would be that noise over sqrt(frames), plus the fixed errors a displacement cancels.
    """
    rows = np.asarray(rows, np.int64)
    cols = np.asarray(cols, np.int64)
    return np.maximum(np.sqrt(_around(np.asarray(variance, np.float64), rows, cols, shape)),
                      min_error)


def neighbourhood_mean(values: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                       shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Mean (N, 3) of ``values`` over the 3 x 3 cells around each cell, and their count (N,).

    Only cells with finite values count; a cell with none around it gets 0 and count 0.
    """
    values = np.where(np.isfinite(values), values, np.nan)
    grid = np.zeros(shape + (3,))
    count = np.zeros(shape)
    ok = np.isfinite(values).all(axis=1)
    grid[rows[ok], cols[ok]] = values[ok]
    count[rows[ok], cols[ok]] = 1.0
    total = cv2.boxFilter(grid, -1, (3, 3), normalize=False,
                          borderType=cv2.BORDER_CONSTANT)
    n = cv2.boxFilter(count, -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
    counted = n[rows, cols]
    mean: np.ndarray = total[rows, cols] / np.maximum(counted, 1.0)[:, None]
    return mean, counted


def _around(values2: np.ndarray, rows: np.ndarray, cols: np.ndarray,
            shape: tuple[int, int]) -> np.ndarray:
    """Mean (N, 3) of squared errors over the 3 x 3 cells around each cell (finite ones).

    Noise varies smoothly with the light, and one cell's square is a poor estimate of its
    variance; a cell with no finite neighbour is not trusted (inf).
    """
    mean2, counted = neighbourhood_mean(values2, rows, cols, shape)
    mean2[counted == 0] = np.inf              # no neighbours to judge by: not trusted
    return mean2


def _stencils(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int], weight: np.ndarray,
              at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The leave-one-out weighted quadratic fit of :func:`local_fit` as a linear stencil.

    For each cell of ``at``: (neighbour indices (M, K) into the N cells, 0 where none;
    coefficients (M, K), 0 there; variance factor (M,)) such that the fit's centre value is
    ``(coefficients[..., None] * values[neighbours]).sum(axis=1)``: the centre value
    e0^T A^-1 Phi^T W v is linear in the values v, so the stencil is found once per reference
    and a frame costs one gather and one weighted sum.
    """
    m = len(at)
    grid_i = np.full(shape, -1, np.int64)
    grid_i[rows, cols] = np.arange(len(rows))
    nb = _neighbours(grid_i + 1, rows[at], cols[at]) - 1       # (M, K), -1 where none
    grid_w = np.zeros(shape)
    grid_w[rows, cols] = weight
    w = _neighbours(grid_w, rows[at], cols[at])                 # (M, K)
    a = (w @ _OUTER).reshape(m, 6, 6)
    a += (1e-9 * np.trace(a, axis1=1, axis2=2) / 6)[:, None, None] * np.eye(6)
    e0 = np.zeros((m, 6, 1))
    e0[:, 0, 0] = 1.0
    z = np.linalg.solve(a, e0)[:, :, 0] if m else np.zeros((0, 6))
    coef = w * (z @ _PHI.T)                                     # (M, K)
    factor = z[:, 0].copy()
    bad = (np.count_nonzero(w > 0, axis=1) < 9) | ~np.isfinite(factor) | (factor <= 0)
    coef[bad] = 0.0
    factor[bad] = np.inf
    return np.maximum(nb, 0), coef, factor


class CellWeights:
    """The per-cell weights of one reference: expected errors and the cleaning stencils.

    Built once per reference, in its background preparation (a few ms): ``error`` (N, 3) m,
    each cell's expected displacement error; ``noisy`` the cells cleaned in every frame
    (expected error above ``noisy_factor`` x ``min_error``) with their stencils; ``effective``
    (N, 3) m, the expected error after cleaning (a cleaned cell's combination of its own
    value and its neighbours' fit: 1 / (1 / sigma^2 + 1 / prediction variance)), which gives
    the noise of the resultant and of the map (:meth:`propagated`).
    """

    def __init__(self, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int],
                 rest: np.ndarray, nominal: np.ndarray, frames: int,
                 params: WeightParams, frame_variance: np.ndarray | None = None) -> None:
        """Expected errors and stencils of the reference ``rest`` of ``frames`` frames.

        ``frame_variance`` (N, 3) m^2: each cell's scatter over the reference frames (pad
        frame; :meth:`~.reference.ReferenceBuilder.scatter`).  With more than one reference
        frame it gives the frame's noise (:func:`scatter_error`); otherwise the reference's
        roughness does (:func:`expected_error`).
        """
        self.params = params
        self.rows = np.asarray(rows, np.int64)
        self.cols = np.asarray(cols, np.int64)
        self.shape = shape
        if frames > 1 and frame_variance is not None:
            sigma = scatter_error(self.rows, self.cols, frame_variance, shape,
                                  params.min_error)
        else:
            sigma = expected_error(self.rows, self.cols, rest, nominal, shape,
                                   params.min_error)
        self.error = sigma * np.sqrt(1.0 + 1.0 / max(int(frames), 1))
        var = self.error ** 2
        mean_var = np.mean(var, axis=1)
        noisy = np.flatnonzero(np.max(self.error, axis=1)
                               > params.noisy_factor * params.min_error)
        nb, coef, factor = _stencils(self.rows, self.cols, shape, 1.0 / mean_var, noisy)
        ok = np.isfinite(factor)
        self.noisy, self._nb, self._coef = noisy[ok], nb[ok], coef[ok]
        # the fit's variance: factor / w, w the mean inverse variance over the axes, spread
        # over the axes in the proportions of the cell's own expected errors; plus the
        # quadratic's own departure from a real field
        own = var[self.noisy]
        self._own_var = own
        self._pred_var = (factor[ok, None] * own / mean_var[self.noisy, None]
                          + params.model_error ** 2)
        effective = var.copy()
        effective[self.noisy] = 1.0 / (1.0 / own + 1.0 / self._pred_var)
        self.effective = np.sqrt(effective)

    def clean(self, disp: np.ndarray) -> np.ndarray:
        """``disp`` (N, 3) m with the noisy cells cleaned (module docstring, step 2).

        Every reference cell must hold a value (missing ones filled from their neighbours
        first: :meth:`TractionSolver.fill_missing`); ``disp`` itself when nothing is noisy.
        """
        if len(self.noisy) == 0:
            return disp
        pred = np.einsum("mk,mkc->mc", self._coef, disp[self._nb])
        own = disp[self.noisy]
        pred_var = self._pred_var
        if self.params.model_error_relative > 0:
            pred_var = pred_var + (self.params.model_error_relative * pred) ** 2
        t = np.abs(own - pred) / np.sqrt(self._own_var + pred_var)
        huber = np.minimum(1.0, self.params.huber_k / np.maximum(t, 1e-12))
        w_own = huber / self._own_var
        w_pred = 1.0 / pred_var
        out = disp.copy()
        out[self.noisy] = (w_own * own + w_pred * pred) / (w_own + w_pred)
        return out

    def propagated(self, rows: np.ndarray) -> np.ndarray:
        """Standard deviation of each linear functional ``rows`` (R, 3N) of the cleaned field.

        sqrt(sum_j R_j^2 sigma_j^2) with sigma the effective errors: independent cells
        (cleaning correlates neighbours a little; ignored).
        """
        r = np.asarray(rows)
        var = (self.effective.reshape(-1) ** 2).astype(r.dtype)
        return np.sqrt(np.asarray((r * r) @ var, np.float64))


@dataclass
class ReferenceNoise:
    """What a reference's cells' expected errors give the touch outputs (all fixed at tare).

    ``moment`` (2,): the resultant's M_x, M_y noise in units of ``displacement_noise``;
    ``map`` (N,) N: each cell's map-force noise (the contact state's ripples); ``centroid``
    (N,) N: that beyond ``displacement_noise``'s (the map centroid's uncertainty) and
    ``support`` (N,) N: each cell's constrained-pressure noise (the contact area), both only
    on a pad with noisy cells. Without weights: the solver's ``moment`` and nothing else.
    """

    moment: tuple[float, float]
    map: np.ndarray | None = None
    centroid: np.ndarray | None = None
    support: np.ndarray | None = None


def reference_noise(weights: CellWeights | None, solver: Any,
                    displacement_noise: float) -> ReferenceNoise:
    """The noise model of a reference from its :class:`CellWeights` and its inversion.

    ``solver``: the reference's :class:`~tactile_sl_decoder.touch.traction.TractionSolver`.
    The moments' noise is never below that of ``displacement_noise`` on every cell (a clean
    pad: as without weights), nor is the support's.
    """
    if weights is None:
        return ReferenceNoise(tuple(solver.moment_noise))
    mx, my = weights.propagated(solver.moment_rows()) / displacement_noise
    moment = (max(float(mx), solver.moment_noise[0]), max(float(my), solver.moment_noise[1]))
    map_noise = weights.propagated(solver.normal_map_rows())
    if len(weights.noisy) == 0:
        # on a clean pad the single reference frame's roughness is no better than the
        # setting: the centroid's and the support's noise stay displacement_noise's
        return ReferenceNoise(moment, map_noise)
    clean = displacement_noise * np.sqrt(np.sum(np.square(solver.normal_map_rows(),
                                                          dtype=np.float64), axis=1))
    centroid = np.sqrt(np.maximum(map_noise ** 2 - clean ** 2, 0.0))
    rows = solver.support_pressure_rows()
    support = (None if rows is None else
               np.maximum(weights.propagated(rows), displacement_noise * solver.support_gain))
    return ReferenceNoise(moment, map_noise, centroid, support)
