"""What the images allow for touch: the Cramer-Rao bound of a contact's force and centre.

A benchmark figure, not a touch stage: the touch outputs are functions of the cells'
measured displacements, so how well *any* unbiased estimator can recover a load follows from
how the displacement field depends on the load and how noisy each cell is.  A lighting row
whose force or centroid error sits near this bound is limited by its images (or its points),
not by the touch stage; an acceptance limit below the bound can only be met by luck.

Model (pad frame, SI): the displacement of cell i is u_i(theta) + e_i, e_i independent,
zero-mean Gaussian with per-axis variances v_i (three per cell), and u the simulator's own
elastic response to the scene's load (:mod:`tactile_sl_sim.loads`: the load's traction on a
fine grid, :func:`tactile_sl_common.elasticity.surface_displacement`, sampled bilinearly at the
cells' rest positions).  theta = (f_x, f_y, f_z, x, y, a): the force vector, the centre and
the radius of the load's profile; the estimator is granted the profile's *shape* (Hertz,
punch, ...), which makes the bound optimistic, a true lower bound.  The Fisher information
of independent Gaussian data whose mean depends on theta (Kay, *Fundamentals of Statistical
Signal Processing: Estimation Theory*, 1993, eq. 3.31 with a fixed diagonal covariance) is

    J = sum_i sum_axes (du_i/dtheta)^T (du_i/dtheta) / v_i

and the covariance of any unbiased estimate of theta is at least J^-1 (Kay eq. 3.24).  The
derivatives are central differences of the model (exact for the force, which u is linear in).

The variances come from repeated draws of the same scene (:func:`draw_variance`: each
cell's sample variance over the draws, the displacement's error being that of the frame and
of the reference together, averaged over the cell's 3 x 3 neighbourhood:
:func:`smooth_variance`), or from the image bound of each point
(:func:`~tactile_sl_decoder.tooling.centre_bound.frame_point_bounds`, a 3-D mean square per
point, split over the axes as the measured noise is: :func:`image_variance`).  Inverting a
sample variance of k degrees of freedom overstates the information by k / (k - 2) on
average (the mean of an inverse chi-square), so the information from draws is scaled back by
that factor.  No rclpy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_sl_decoder.stereo.stereo import StereoRig
from tactile_sl_decoder.tooling.centre_bound import cell_point_bounds
from tactile_sl_decoder.tooling.touch_metrics import cell_keys, key_cells
from tactile_sl_decoder.touch.weights import neighbourhood_mean
from tactile_sl_sim.contact import FieldGrid, PadParams
from tactile_sl_sim.loads import LoadContact, is_load
from tactile_sl_sim.optics import RigParams

PARAMETERS = ("fx", "fy", "fz", "x", "y", "radius")
"""What the estimator does not know: the force (N), the centre (m) and the profile's radius (m)."""
_STEPS = np.array([1e-3, 1e-3, 1e-3, 2e-5, 2e-5, 5e-5])
"""Central-difference steps of :data:`PARAMETERS` (N, N, N, m, m, m)."""
MIN_CELLS = 16
"""A frame whose draws share fewer cells has no bound (the reference's own minimum)."""
GRID_SPACING = 4e-5
"""m: the field grid of the model (the simulator's own, docs/camera.md)."""


def _field(load: LoadContact, rest_xy: np.ndarray, spacing: float) -> np.ndarray:
    """(N, 3) displacement (m) of the cells at ``rest_xy`` under ``load`` (pad frame).

    The simulator's own ground truth (:class:`tactile_sl_sim.contact.FieldGrid`) on a square
    grid just covering the cells and the load.
    """
    reach = load.reach + 2 * spacing
    half = max(float(np.abs(rest_xy).max()), abs(load.x) + reach, abs(load.y) + reach)
    half = spacing * math.ceil(half / spacing + 1)
    n = int(round(2 * half / spacing)) + 1
    grid = FieldGrid.build([load], PadParams(), x0=-half, y0=-half, spacing=spacing,
                           nx=n, ny=n)
    return grid.sample(rest_xy[:, 0], rest_xy[:, 1])


def load_jacobian(load: LoadContact, rest_xy: np.ndarray,
                  spacing: float = GRID_SPACING) -> np.ndarray:
    """(N, 3, 6) derivative of each cell's displacement by :data:`PARAMETERS` at ``load``.

    ``rest_xy`` (N, 2): the cells' rest positions in the pad frame (m).  The load keeps its
    profile, elastomer and torque; only the six parameters move.
    """
    rest_xy = np.asarray(rest_xy, np.float64).reshape(-1, 2)
    base = np.array([*load.force, load.x, load.y, load.radius], np.float64)
    out = np.empty((len(rest_xy), 3, len(PARAMETERS)))
    for k, step in enumerate(_STEPS):
        fields = []
        for sign in (1.0, -1.0):
            p = base.copy()
            p[k] += sign * step
            if k == 2 and p[2] > 0:          # a load presses: difference on the pressing side
                p[2] = 0.0
            moved = LoadContact(radius=float(p[5]), profile=load.profile, x=float(p[3]),
                                y=float(p[4]), force=(float(p[0]), float(p[1]), float(p[2])),
                                torque=load.torque, elastomer=load.elastomer,
                                length=load.length, angle=load.angle)
            fields.append((_field(moved, rest_xy, spacing), p[k]))
        (plus, at_plus), (minus, at_minus) = fields
        out[:, :, k] = (plus - minus) / (at_plus - at_minus)
    return out


def draw_variance(errors: np.ndarray) -> tuple[np.ndarray, int]:
    """Per-cell, per-axis sample variance (m^2) of displacement errors over draws, and its dof.

    ``errors`` (D, N, 3): estimate minus truth of the same N cells in D draws of one frame
    (same load, independent noise).  The mean over the draws (a bias the draws share) is not
    noise and is removed.
    """
    e = np.asarray(errors, np.float64)
    if e.ndim != 3 or e.shape[0] < 2:
        raise ValueError(f"need (draws >= 2, cells, 3) errors, got shape {e.shape}")
    return e.var(axis=0, ddof=1), e.shape[0] - 1


def smooth_variance(variance: np.ndarray, rows: np.ndarray, cols: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Each cell's variance averaged over the cells present in its 3 x 3 neighbourhood.

    Returns the averaged (N, 3) variances and how many cells each average holds (N,).  A
    sample variance of a few draws is itself noisy (of 5 degrees of freedom, one cell in a
    hundred comes out below a quarter of its true value, and inverted it would claim four
    times the information); the light, the shadows and the vignetting that set the noise
    vary over several cells, so the neighbours' variances are samples of nearly the same one
    (as :mod:`tactile_sl_decoder.touch.weights` averages its squared residuals).
    """
    r = np.asarray(rows, np.int64) - int(np.min(rows, initial=0))
    c = np.asarray(cols, np.int64) - int(np.min(cols, initial=0))
    shape = (int(r.max(initial=0)) + 1, int(c.max(initial=0)) + 1)
    return neighbourhood_mean(np.asarray(variance, np.float64), r, c, shape)


def image_variance(measured: np.ndarray, point_bound_m2: np.ndarray) -> np.ndarray:
    """(N, 3) per-axis variances whose sum per cell is ``point_bound_m2`` (N,).

    The image bound of a point is a 3-D mean square; it is split over the axes in the shares
    of the measured noise ``measured`` (N, 3) (the stereo geometry sets them: depth is worse).
    """
    v = np.asarray(measured, np.float64)
    total = v.sum(axis=1, keepdims=True)
    share = np.divide(v, total, out=np.full_like(v, 1.0 / 3.0), where=total > 0)
    return share * np.asarray(point_bound_m2, np.float64).reshape(-1, 1)


def _inverse(variance: np.ndarray) -> np.ndarray:
    """1 / variance, 0 where it is infinite, NaN or 0 (an axis that carries nothing)."""
    v = np.asarray(variance, np.float64)
    return np.where(np.isfinite(v) & (v > 0), 1.0 / np.where(v > 0, v, 1.0), 0.0)


def fisher_information(jacobian: np.ndarray, variance: np.ndarray,
                       dof: int | None = None) -> np.ndarray:
    """(P, P) information of the parameters (Kay 1993, eq. 3.31, diagonal noise).

    ``jacobian`` (N, 3, P), ``variance`` (N, 3) m^2 (an infinite or NaN variance: the axis
    carries nothing).  ``dof``: the variances are sample variances of that many degrees of
    freedom; the information is scaled by (dof - 2) / dof, the mean of an inverse
    chi-square, so that noisy variances do not overstate it (dof <= 2: none exists, the
    mean is infinite; the bench asks for 5 or more draws).
    """
    jac = np.asarray(jacobian, np.float64)
    w = _inverse(variance)
    info = np.einsum("nap,na,naq->pq", jac, w, jac)
    if dof is not None and dof > 2:
        info *= (dof - 2) / dof
    return info


@dataclass(frozen=True)
class TouchBound:
    """Lower bounds of a load's estimates (standard deviations; SI, pad frame)."""

    covariance: np.ndarray     # (6, 6) over PARAMETERS

    def sd(self, name: str) -> float:
        k = PARAMETERS.index(name)
        return float(np.sqrt(self.covariance[k, k]))

    @property
    def normal_force_sd(self) -> float:
        """N: the normal force's."""
        return self.sd("fz")

    @property
    def centre_rms(self) -> float:
        """m: the centre's root-mean-square 2-D error, sqrt(var x + var y)."""
        return float(np.hypot(self.sd("x"), self.sd("y")))


def load_bound(jacobian: np.ndarray, variance: np.ndarray, dof: int | None = None
               ) -> TouchBound:
    """The bound on all six :data:`PARAMETERS` (none known to the estimator)."""
    info = fisher_information(jacobian, variance, dof)
    return TouchBound(np.linalg.pinv(info, hermitian=True))


def variance_shares(jacobian: np.ndarray, variance: np.ndarray, name: str = "fz") -> np.ndarray:
    """(N,) each cell's share of the variance of the efficient estimate of one parameter.

    The efficient (maximum-likelihood, linearised) estimate is theta = C J^T W d with
    C = J^-1 the bound: parameter k takes r_i = (C J^T W)_k,i from cell i, whose noise adds
    r_i^2 v_i to its variance; the shares sum to 1.  Where the force's noise comes from.
    """
    v = np.asarray(variance, np.float64)
    w = _inverse(v)
    jac = np.asarray(jacobian, np.float64)
    cov = np.linalg.pinv(fisher_information(jac, v), hermitian=True)
    k = PARAMETERS.index(name)
    r = np.einsum("p,nap->na", cov[k], jac) * w
    part = np.sum(r * r * np.where(w > 0, v, 0.0), axis=1)
    total = float(part.sum())
    return part / total if total > 0 else part


def within_share(limit: float, sd: float) -> float:
    """Probability that an unbiased Gaussian estimate of scatter ``sd`` is within +-``limit``."""
    if not sd > 0:
        return 1.0
    return math.erf(limit / (sd * math.sqrt(2.0)))


def centre_within_share(limit: float, rms: float) -> float:
    """Probability that a 2-D error of root-mean-square ``rms`` is within ``limit``.

    Isotropic Gaussian in both axes (variance rms^2 / 2 each): the Rayleigh distribution,
    P(r <= L) = 1 - exp(-L^2 / rms^2).
    """
    if not rms > 0:
        return 1.0
    return 1.0 - math.exp(-(limit / rms) ** 2)


# ---------------------------------------------------------------------- a scene's frames


@dataclass(frozen=True)
class FrameBound:
    """The bounds of one loaded frame of a scene rendered in several draws."""

    frame: int                  # the scene's frame index
    load: LoadContact           # the true load
    force: np.ndarray           # (3,) N, the force it transmits
    cells: int                  # cells decoded in every draw
    draws: int
    points: TouchBound          # from the draws' measured displacement noise
    images: TouchBound | None   # from the images' point bounds (None: not computed)
    rest_xy: np.ndarray         # (N, 2) m, the cells' rest positions
    noise: np.ndarray           # (N, 3) m^2, the draws' displacement variance per axis
    image_noise: np.ndarray | None   # (N, 3) m^2, the images' (None: not computed)
    force_share: np.ndarray     # (N,) each cell's share of the efficient normal force's
    """variance, with the draws' noise (:func:`variance_shares`)"""


def _common(errors: list[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cells, errors (D, N, 3), rest_xy (N, 2)) of the cells every draw decoded."""
    cells = errors[0].cells
    for e in errors[1:]:
        cells = np.intersect1d(cells, e.cells, assume_unique=True)
    stacked = np.stack([e.errors[np.searchsorted(e.cells, cells)] for e in errors])
    first = errors[0]
    return cells, stacked, first.rest_xy[np.searchsorted(first.cells, cells)]


def _point_bounds(renderer: Any, scene: Any, frame: int) -> tuple[np.ndarray, np.ndarray]:
    """(cells ascending, image bound m^2 of each cell's 3-D point) in frame ``frame``."""
    rig = StereoRig(renderer.rig.left_info, renderer.rig.right_info)
    spacing_px = RigParams.GLYPH_SPACING_PX * scene.rig.focal[0] / RigParams().focal[0]
    rows, cols, bounds = cell_point_bounds(renderer, rig, scene.contacts_at(frame),
                                           scene.nuisances_at(frame), scene.seed, frame,
                                           spacing_px)
    keys = cell_keys(rows, cols)
    order = np.argsort(keys)
    return keys[order], np.asarray(bounds, np.float64)[order]


def _lookup(table: tuple[np.ndarray, np.ndarray], cells: np.ndarray) -> np.ndarray:
    """The table's bound of each of ``cells`` (inf where it has none)."""
    keys, bounds = table
    if not len(keys):
        return np.full(len(cells), np.inf)
    at = np.clip(np.searchsorted(keys, cells), 0, len(keys) - 1)
    return np.where(keys[at] == cells, bounds[at], np.inf)


def scene_bounds(scene: Any, draws: list[dict[int, Any]], renderer: Any | None = None
                 ) -> list[FrameBound]:
    """The bounds of every frame of ``scene`` that carries one load, over its draws.

    ``draws``: per draw (same scene, other noise seeds) its
    :func:`~tactile_sl_decoder.tooling.bag_runs.displacement_errors`.  ``renderer``: the
    scene's renderer, for the image bound (rendered at the scene's own seed: the bound
    depends on the signal, not on the draw); None leaves it out.
    """
    out = []
    rest_table = None
    for frame in range(scene.frames):
        stamp = scene.stamp_ns(frame)
        frames = [d[stamp] for d in draws if stamp in d]
        loads = [c for c in scene.contacts_at(frame) if is_load(c) and c.active]
        if len(frames) < 2 or len(frames) < len(draws) or len(loads) != 1:
            continue
        cells, errors, rest_xy = _common(frames)
        if len(cells) < MIN_CELLS:
            continue
        variance, dof = draw_variance(errors)
        variance, pooled = smooth_variance(variance, *key_cells(cells))
        dof *= int(np.median(pooled))
        jac = load_jacobian(loads[0], rest_xy)
        images = image_noise = None
        if renderer is not None:
            if rest_table is None:
                rest_table = _point_bounds(renderer, scene, 0)
            squared = (_lookup(rest_table, cells)
                       + _lookup(_point_bounds(renderer, scene, frame), cells))
            image_noise = image_variance(variance, squared)
            images = load_bound(jac, image_noise)
        out.append(FrameBound(frame, loads[0], np.asarray(loads[0].applied_force, np.float64),
                              len(cells), len(frames), load_bound(jac, variance, dof), images,
                              rest_xy, variance, image_noise, variance_shares(jac, variance)))
    return out
