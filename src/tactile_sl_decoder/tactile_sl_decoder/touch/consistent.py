"""The normal displacement a traction-free surface allows, on a pad with noisy cells.

Under harsh light the normal displacement of a cell is off by 5-9 um RMS against 2.5 um in
clean light (bags/light_scenes.yaml), and cleaning the noisiest cells from their neighbours
(:mod:`.weights`) leaves most of it: a neighbour fit cannot tell a smooth indentation from
smooth noise.  The elastic model can.  Outside the contact the surface of the pad carries no
traction (Hertz's boundary condition, p = 0 outside the contact area: Johnson, Contact
Mechanics, 1985, sec. 4.2), so the normal displacement of *every* cell is produced by the
pressure on the few cells S in contact:

    u_z,i = sum_{j in S} G_zz(r_i - r_j) p_j

with G the surface Green's function the traction inversion uses
(:func:`tactile_sl_common.elasticity.cell_kernel`: Boussinesq-Cerruti, Johnson 1985,
eqs. 2.18-2.19, integrated over each cell; or the bonded layer's).  That is |S| unknowns for
N cells: the pressure is fitted to the measured u_z by generalised least squares, each cell
weighted by the inverse of its expected error after cleaning (``CellWeights.effective``; the
best linear unbiased estimate, Aitken 1935, Proc. R. Soc. Edinburgh 55), with a weak
Tikhonov term,

    p = (G_S^T W G_S + a s I)^-1 G_S^T W u_z,  s = mean diag of G_S^T W G_S, a = FIT_WEIGHT

(Hansen, Rank-Deficient and Discrete Ill-Posed Problems, SIAM 1998, eq. 5.1, with the data
weighted), and the displacement reported is G_S p: the part of the noise that no pressure on
the contact can produce (on the harsh scenes, all but |S| of N dimensions of it) is gone.

The model is tested on every frame before it is used: the weighted residual
chi^2 = sum_i w_i (u_i - (G_S p)_i)^2 over the decoded cells has N - |S| degrees of freedom
when the model holds (Press et al., Numerical Recipes, 3rd ed., 2007, sec. 15.1: chi-square
as the goodness of fit of a weighted least-squares fit); on the harsh scenes chi^2 / dof is
0.6-1.9 (growing with the load: glyphs on the deformed, shaded surface), without the
contact's pressure (S empty) 35 at 0.1 N and 850-13600 from 0.5 N.  Above ``CHI2_LIMIT`` the
model does not explain the field (a contact the support missed, a pull, a pad whose light
changed after the tare) and the measured field is kept.  Also kept when S holds more than
``MAX_SHARE`` of the cells: the fit then removes less than half the noise and costs the most.

The fitted pressure is also an estimate of the contact's normal force (its sum) and
centroid, each with its variance from the fit's covariance (G_S^T W G_S)^-1: the stage
combines them with the resultant's (:meth:`ConsistentField.normal_force`) and with the
map's and the resultant's centroids (:func:`~.contact.contact_state`) by inverse variance.
Noise far from the contact cannot pull them: those cells carry no unknown.

S is the support of the constrained pressure (:meth:`~.traction.TractionSolver.support_pressure`:
cells pressing by ``support_sigmas`` x their noise) or, where that cannot locate the edge of a
faint contact, the map's cells above the area fraction of its peak, in the 8-connected parts
that stand out of the noise (:func:`~.contact.without_ripples`: a noisy map's scattered
peaks are not fitted as pressing); grown by one cell (the cells the edge cuts).  A faint
contact's pressure is taken uniform over blocks of
``COARSE_BLOCK`` x ``COARSE_BLOCK`` cells (those S touches): the data that cannot locate its
edge cannot resolve it at a cell's scale either, and a quarter of the unknowns removes more
of the noise (on the harsh 0.1 N frames 32-78 unknowns, 64-129 before the ripples were
dropped, instead of 415-431 cells, over the ``MAX_SHARE`` a per-cell fit may have).

Only the normal component is fitted: for a nearly incompressible pad the normal pressure
moves the surface along its normal and the shear tractions within it
(the coupling is (1 - 2 nu) / (2 (1 - nu)) of either, 2 % at nu = 0.49), and the in-plane
error is about 3 x smaller than the normal one; the in-plane displacement stays as measured.

Only pads where noise is the rule are fitted (:func:`for_reference`: more than
``MIN_NOISY_SHARE`` of the cells cleaned by :class:`~.weights.CellWeights`; 58-81 % on the
harsh-light scenes, rendered with Hertz loads or indenter shapes): there the neighbours the
cleaning predicts a cell from are noisy themselves.  A few noisy cells on a clean pad (a dark
corner, dust: 2 of 728 on some slip scenes) are cleaned from clean neighbours, and a clean
pad's own error (2.5 um RMS) is close to what a real elastomer departs from the linear model:
their outputs keep their bytes.  Per frame: two N x N float32 products, the gather
of an |S| x |S| block of G^T W G (prepared with the reference) and its Cholesky
factorisation (~0.4 ms for 250 cells).
"""
from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from tactile_sl_decoder.touch.cholesky import cho_factor_upper, cho_solve_upper

FIT_WEIGHT = 1e-3
"""a: the Tikhonov weight of the pressure fit, relative to the mean diagonal of its normal
matrix (1e-5 to 1e-3 give the same field within 0.05 um on the harsh scenes)."""
CHI2_LIMIT = 4.0
"""The fit is used while chi^2 per degree of freedom is within this (its residual within
twice the cells' expected errors)."""
MIN_NOISY_SHARE = 0.25
"""A reference is fitted when more than this share of its cells are noisy."""
MAX_SHARE = 0.5
"""The fit is skipped when its unknowns are more than this share of the reference's cells."""
COARSE_BLOCK = 2
"""A contact too faint for the support to locate its edge is fitted with a pressure uniform
over blocks of this many x this many cells."""


class _Basis:
    """The unknowns of a fit: a pressure uniform over each element (a cell, or a block).

    ``forward_t`` (E, N) float32: u_z of every cell per unit force on each of the element's
    cells (G^T's rows); ``normal`` (E, E) float32: G^T W G; ``of_cell`` (N,): each cell's
    element; ``count`` (E,): its cells; ``xy`` (E, 2): where its force acts (its cells' mean
    position), or None.
    """

    def __init__(self, g: np.ndarray, weight32: np.ndarray, of_cell: np.ndarray,
                 xy: np.ndarray | None) -> None:
        n = g.shape[0]
        elements = int(of_cell.max()) + 1 if n else 0
        member = np.zeros((n, elements), np.float32)
        member[np.arange(n), of_cell] = 1.0
        ge = g if elements == n and np.array_equal(of_cell, np.arange(n)) else g @ member
        self.of_cell = of_cell
        self.count = member.sum(axis=0).astype(np.float64)
        self.forward_t = np.ascontiguousarray(ge.T)
        self.normal = np.ascontiguousarray(ge.T @ (ge * weight32[:, None]))
        self.xy = None if xy is None else member.T.astype(np.float64) @ xy / self.count[:, None]


class ConsistentField:
    """The normal displacement fitted by the pressure on the contact, for one reference.

    ``forward`` (N, N): u_z of each reference cell per unit normal force on each (the
    traction solver's zz block of G); ``sigma`` (N,) m: each cell's expected error of u_z
    (after cleaning); ``rows``, ``cols`` the cells on a grid of ``shape``.  Built with the
    reference (G^T W G: one N x N x N product, ~20-40 ms for 728 cells).
    """

    def __init__(self, forward: np.ndarray, sigma: np.ndarray, rows: np.ndarray,
                 cols: np.ndarray, shape: tuple[int, int], xy: np.ndarray | None = None,
                 resultant_sd: float = 0.0) -> None:
        g = np.asarray(forward, np.float32)
        n = g.shape[0]
        if g.shape != (n, n) or np.shape(sigma) != (n,):
            raise ValueError(f"forward must be (N, N) and sigma (N,), got {g.shape}, "
                             f"{np.shape(sigma)}")
        self.shape = (int(shape[0]), int(shape[1]))
        self.rows = np.asarray(rows, np.int64)
        self.cols = np.asarray(cols, np.int64)
        self.xy = None if xy is None else np.asarray(xy, np.float64)[:, :2]
        self.resultant_sd = float(resultant_sd)
        """N: the resultant's normal force noise (0: the fitted force is not combined)."""
        self.weight = 1.0 / np.asarray(sigma, np.float64) ** 2
        self._weight32 = self.weight.astype(np.float32)
        # G^T (its rows: the data term G^T W u; G = its transpose: the fitted field) and
        # the normal matrix G^T W G, both float32 (the frame's products are memory-bound),
        # per cell and per block of COARSE_BLOCK x COARSE_BLOCK cells
        self._cells = _Basis(g, self._weight32, np.arange(n), self.xy)
        blocks = ((self.rows // COARSE_BLOCK) * (self.shape[1] // COARSE_BLOCK + 1)
                  + self.cols // COARSE_BLOCK)
        self._blocks = _Basis(g, self._weight32, np.unique(blocks, return_inverse=True)[1]
                              .reshape(-1), self.xy)
        self.last_cells = 0                  # unknowns of the last frame's fit (0: none)
        self.last_chi2 = float("nan")        # its chi^2 per degree of freedom
        self.last_centroid: tuple[np.ndarray, np.ndarray] | None = None
        """The last fit's pressure centroid (2,) m and its variance (2,) m^2 per axis (with
        ``xy``, a fit used, pressing): :meth:`fit`."""
        self.last_force: tuple[float, float] | None = None
        """The last fit's normal force (N, pressing > 0) and its variance (N^2) (a fit
        used, pressing)."""

    def contact_cells(self, core: np.ndarray) -> np.ndarray:
        """``core`` (N,) bool grown by one cell (8-connected): the unknowns S."""
        grid = np.zeros(self.shape, np.uint8)
        grid[self.rows[core], self.cols[core]] = 1
        grown = cv2.dilate(grid, np.ones((3, 3), np.uint8))
        return np.flatnonzero(grown[self.rows, self.cols])

    def fit(self, uz: np.ndarray, valid: np.ndarray, core: np.ndarray,
            coarse: bool = False) -> np.ndarray | None:
        """The fitted u_z (N,) m of every reference cell, or None where the model fails.

        ``uz`` (N,) the cleaned normal displacement (missing cells filled), ``valid`` the
        cells decoded in this frame (the chi^2 test counts only those), ``core`` the cells in
        contact (before growing; none: the model of an untouched pad, u_z = 0); ``coarse``:
        the pressure uniform over blocks of ``COARSE_BLOCK`` cells (those S touches).  None
        when the unknowns are more than ``MAX_SHARE`` of the cells or chi^2 per degree of
        freedom exceeds ``CHI2_LIMIT`` (the measured field is kept then).
        """
        n = len(uz)
        basis = self._blocks if coarse else self._cells
        cells = self.contact_cells(core) if np.any(core) else np.zeros(0, np.int64)
        if coarse:
            cells = np.unique(basis.of_cell[cells])
        self.last_cells, self.last_chi2 = len(cells), float("nan")
        self.last_centroid = self.last_force = None
        if len(cells) > MAX_SHARE * n:
            return None
        u = np.asarray(uz, np.float64)
        pred = np.zeros(n)
        if len(cells):
            # only the rows of S are read: G_S^T, and G^T W G's block, rows then columns
            g_s = basis.forward_t[cells]
            data = g_s @ (self._weight32 * u.astype(np.float32))
            # (symmetric: the transpose of the C-ordered block is the Fortran-ordered one)
            a = np.array(basis.normal[cells][:, cells].T, np.float64, order="F")
            diagonal = a.reshape(-1, order="F")[::len(cells) + 1]       # a view
            diagonal += FIT_WEIGHT * float(np.mean(diagonal))
            try:
                factor = cho_factor_upper(a, overwrite_a=True)
            except np.linalg.LinAlgError:      # (G^T W G is positive definite: rounding)
                return None
            p = cho_solve_upper(factor, data)
            pred = (g_s.T @ p.astype(np.float32)).astype(np.float64)
        dof = int(np.count_nonzero(valid)) - len(cells)
        if dof <= 0:
            return None
        resid = (u - pred)[valid]
        self.last_chi2 = float(np.sum(self.weight[valid] * resid * resid)) / dof
        if not self.last_chi2 <= CHI2_LIMIT:
            return None
        if len(cells):
            birge = max(1.0, self.last_chi2)
            count = basis.count[cells]            # p is the force on each of their cells
            force = -float(count @ p)
            if force > 0:
                self.last_force = (force,
                                   birge * float(count @ cho_solve_upper(factor, count)))
            if basis.xy is not None:
                self.last_centroid = _centroid(-p, basis.xy[cells], factor, birge, count)
        return pred

    def normal_force(self, resultant: float) -> float | None:
        """The normal force (N, > 0 pressing) combining the resultant's and the last fit's.

        Per inverse variance (the minimum-variance unbiased combination of two estimates):
        the resultant's noise is ``resultant_sd``, the fitted pressure's sum has the variance
        1^T (G_S^T W G_S)^-1 1 (Aitken 1935), scaled like the centroid's.  None when the last
        frame was not fitted, either does not press, or ``resultant_sd`` is 0.
        """
        if self.last_force is None or not resultant > 0 or not self.resultant_sd > 0:
            return None
        force, var = self.last_force
        w_res, w_fit = 1.0 / self.resultant_sd ** 2, 1.0 / max(var, 1e-30)
        return (w_res * resultant + w_fit * force) / (w_res + w_fit)


def for_reference(solver: Any, weights: Any, shape: tuple[int, int],
                  xy: np.ndarray | None = None, displacement_noise: float = 0.0
                  ) -> ConsistentField | None:
    """The fit of a reference, or None where it is not wanted (module docstring).

    Also None with ``WeightParams.fit_normal`` off.  ``solver``: its
    :class:`~.traction.TractionSolver`; ``weights``: its :class:`~.weights.CellWeights`
    (None with the weights off); ``xy`` (N, 2) the cells' rest positions (pad frame): the
    fit's pressure centroid (:attr:`ConsistentField.last_centroid`).  The resultant's
    normal force noise is propagated from the cells' expected errors, never below
    ``displacement_noise`` on every cell's.
    """
    if weights is None or not weights.params.fit_normal or (
            len(weights.noisy) <= MIN_NOISY_SHARE * len(weights.rows)):
        return None
    row = np.asarray(solver.normal_force_row(), np.float64)
    resultant_sd = max(float(weights.propagated(row[None, :])[0]),
                       displacement_noise * float(np.linalg.norm(row)))
    return ConsistentField(solver.normal_forward(), weights.effective[:, 2], solver.rows,
                           solver.cols, shape, xy, resultant_sd)


def _centroid(press: np.ndarray, xy: np.ndarray, factor: np.ndarray, birge: float = 1.0,
              count: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """Centroid (2,) of the fitted pressure and its variance (2,); None if it does not press.

    ``press`` N per cell of each unknown (> 0 pressing), ``xy`` (|S|, 2) where each acts,
    ``count`` its cells (1 each when None).

    c = sum p_j r_j / P is exact for a pressure on the pad's plane; to first order its error
    is v^T dp with v_j = (r_j - c) / P, and the generalised least-squares pressure's
    covariance is (G_S^T W G_S)^-1 (Aitken 1935; with the weak Tikhonov term, its inverse
    normal matrix, whose Cholesky ``factor`` the fit made), so var c = v^T A^-1 v, times
    ``birge``, the fit's chi^2 per degree of freedom when above 1 (Birge, Phys. Rev. 40,
    207, 1932: errors scaled by how far the residual exceeds the expected one).
    """
    count = np.ones(len(press)) if count is None else count
    total = float(count @ press)
    if not total > 0:
        return None
    c = (count * press) @ xy / total
    v = count[:, None] * (xy - c) / total                 # (|S|, 2)
    var = birge * np.einsum("ka,ka->a", v, cho_solve_upper(factor, v))
    return c, np.maximum(var, 0.0)
