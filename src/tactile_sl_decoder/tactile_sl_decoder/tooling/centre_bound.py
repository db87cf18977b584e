"""What the images allow: the Cramer-Rao lower bound of glyph centres and 3-D points.

A benchmark figure, not a decoder stage: for a rendered frame whose noise-free signal is
known (the simulator renders the same scene without noise), it bounds the error that *any*
unbiased estimator of a glyph's image position can reach, and carries that bound through
the stereo triangulation to a bound on the 3-D point error. A sweep row whose measured
RMSE sits near its bound is limited by the images, not by the decoder; a target below the
bound cannot be met by any per-point measurement of those images.

Model (the simulator's, docs/camera.md): independent pixels, Gaussian noise of variance
``read_sigma**2 + shot_noise * S`` on the linear signal ``S`` (grey levels, before gamma,
quantisation and MJPEG, which only lose information). The glyph's own share G of the
image (:func:`frame_point_bounds`: the print with and without it) is taken as a known
pattern that moves with the centre (u, v), and everything else (the neighbours, the
object seen through the pad, the light) as known too. These choices make the bound
optimistic, i.e. a true lower bound.

Fisher information of a Gaussian whose mean and variance depend on the parameters, for
independent samples (Kay, *Fundamentals of Statistical Signal Processing: Estimation
Theory*, 1993, eq. 3.31, diagonal covariance):

    J_ab = sum_pixels  dG/da dG/db * (1 / var + shot_noise**2 / (2 var**2))

with a, b in {u, v}; the bound on the centre's covariance is J^-1 (Kay eq. 3.24). The 3-D
bound of a point is trace(A_L C_L A_L^T + A_R C_R A_R^T), A the Jacobian of the
triangulated point with respect to that image's pixel position (numerical, the decoder's
own :meth:`StereoRig.triangulate`), the two images' noise independent.
No rclpy.
"""
from __future__ import annotations

from typing import Any, Iterator

import numpy as np
from scipy.ndimage import correlate1d

FOURTH_ORDER = np.array([1.0, -8.0, 0.0, 8.0, -1.0]) / 12.0   # d/dx, exact for quartics


def centre_covariance_bound(signal: np.ndarray, centres: np.ndarray, half_window: int,
                            read_sigma: float, shot_noise: float,
                            glyph_signal: np.ndarray | None = None) -> np.ndarray:
    """(N, 2, 2) lower bound (px^2) of the covariance of each glyph centre (u, v).

    ``signal``: (H, W) noise-free linear signal in grey levels (sets the noise);
    ``glyph_signal``: the glyphs' own share of it (the image minus the image without these
    glyphs), whose slope is what moving a glyph changes; default ``signal`` itself (a lone
    glyph). ``centres`` (N, 2) true pixel positions (u, v); ``half_window``: pixels each side
    of the centre that count (the glyph's whole blurred footprint; other glyphs of
    ``glyph_signal`` must lie outside it). A centre without information (flat window,
    outside the image) gets an infinite bound.
    """
    s = np.asarray(signal, np.float64)
    g = s if glyph_signal is None else np.asarray(glyph_signal, np.float64)
    # Fourth-order central differences: np.gradient's two-point one underestimates the
    # slope of a blurred glyph edge (8 % less information for a 2.5 px Gaussian), which
    # would make the bound too high rather than a lower bound.
    grad_u = correlate1d(g, FOURTH_ORDER, axis=1, mode="nearest")
    grad_v = correlate1d(g, FOURTH_ORDER, axis=0, mode="nearest")
    var = float(read_sigma) ** 2 + float(shot_noise) * np.maximum(s, 0.0)
    with np.errstate(divide="ignore"):
        weight = np.where(var > 0, 1.0 / var + float(shot_noise) ** 2 / (2.0 * var ** 2), 0.0)
    # Window sums of the three products at every pixel at once (integral images).
    prods = np.stack([grad_u * grad_u * weight, grad_u * grad_v * weight,
                      grad_v * grad_v * weight])
    integral = np.zeros((3, s.shape[0] + 1, s.shape[1] + 1))
    integral[:, 1:, 1:] = prods.cumsum(1).cumsum(2)
    c = np.rint(np.asarray(centres, np.float64)).astype(np.int64).reshape(-1, 2)
    h, w = s.shape
    u0 = np.clip(c[:, 0] - half_window, 0, w)
    u1 = np.clip(c[:, 0] + half_window + 1, 0, w)
    v0 = np.clip(c[:, 1] - half_window, 0, h)
    v1 = np.clip(c[:, 1] + half_window + 1, 0, h)
    sums = (integral[:, v1, u1] - integral[:, v0, u1] - integral[:, v1, u0]
            + integral[:, v0, u0])
    fisher = np.empty((len(c), 2, 2))
    fisher[:, 0, 0], fisher[:, 0, 1], fisher[:, 1, 1] = sums
    fisher[:, 1, 0] = fisher[:, 0, 1]
    det = fisher[:, 0, 0] * fisher[:, 1, 1] - fisher[:, 0, 1] ** 2
    cov = np.full((len(c), 2, 2), np.inf)
    ok = det > 1e-12 * np.maximum(fisher[:, 0, 0] * fisher[:, 1, 1], 1e-300)
    cov[ok, 0, 0] = fisher[ok, 1, 1] / det[ok]
    cov[ok, 1, 1] = fisher[ok, 0, 0] / det[ok]
    cov[ok, 0, 1] = cov[ok, 1, 0] = -fisher[ok, 0, 1] / det[ok]
    return cov


def point_error_bound(rig: Any, px_left: np.ndarray, px_right: np.ndarray,
                      cov_left: np.ndarray, cov_right: np.ndarray,
                      step_px: float = 0.01) -> np.ndarray:
    """(N,) lower bound (m^2) of the mean squared 3-D error of each triangulated point.

    ``rig``: the decoder's :class:`~tactile_sl_decoder.stereo.stereo.StereoRig`;
    ``px_left`` / ``px_right`` (N, 2) true raw pixel positions; ``cov_*`` (N, 2, 2) their
    centre bounds (:func:`centre_covariance_bound`). Infinite where a centre has none.
    """
    uv_l = np.asarray(px_left, np.float64).reshape(-1, 2)
    uv_r = np.asarray(px_right, np.float64).reshape(-1, 2)
    base = _points(rig, uv_l, uv_r)
    total = np.zeros(len(uv_l))
    for side, cov in ((0, cov_left), (1, cov_right)):
        jac = np.empty((len(uv_l), 3, 2))
        for axis in range(2):
            moved = [uv_l.copy(), uv_r.copy()]
            moved[side][:, axis] += step_px
            jac[:, :, axis] = (_points(rig, *moved) - base) / step_px
        finite = np.isfinite(cov).all(axis=(1, 2))
        safe = np.where(finite[:, None, None], cov, 0.0)
        total += np.where(finite, np.einsum("nij,njk,nik->n", jac, safe, jac), np.inf)
    return total


def frame_point_bounds(renderer: Any, rig: Any, contacts: Any, nuisances: Any, seed: int,
                       frame_index: int, spacing_px: float) -> np.ndarray:
    """Bound (m^2) of every visible undamaged glyph's point in one simulated stereo frame.

    ``renderer``: the simulator's ``Renderer``; the frame is what ``renderer.render(contacts,
    nuisances, seed, frame_index)`` gives, ``rig`` the decoder's ``StereoRig`` of its cameras.
    The same scene (same seed: same exposures, dust and damage) rendered as its linear signal
    sets the noise; a glyph's own share of it is the signal with only every third row and
    column of glyphs printed minus the signal without any glyph (the image is linear in the
    print), so its neighbours' ink does not count as information about its position. Nine
    such renders cover every glyph; the window of 1.5 spacings holds its whole blurred
    footprint and no other printed glyph. Returns the glyphs in the truth's order (visible,
    undamaged ones).
    """
    return cell_point_bounds(renderer, rig, contacts, nuisances, seed, frame_index,
                             spacing_px)[2]


def cell_point_bounds(renderer: Any, rig: Any, contacts: Any, nuisances: Any, seed: int,
                      frame_index: int, spacing_px: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`frame_point_bounds` with the cells they belong to: (rows, cols, bounds m^2)."""
    full, shares = glyph_shares(renderer, contacts, nuisances, seed, frame_index)
    t = full.truth
    keep = t.visible & ~t.damaged if t.damaged is not None else t.visible
    half = int(np.ceil(1.5 * spacing_px))
    read, shot = float(nuisances.noise_sigma), float(nuisances.shot_noise)
    covs = np.full((2, len(t.rows), 2, 2), np.inf)
    for sel, side, share, _paper in shares:
        sel = sel & keep
        if not sel.any():
            continue
        img, px = (full.left, t.px_left) if side == 0 else (full.right, t.px_right)
        covs[side, sel] = centre_covariance_bound(img, px[sel], half, read, shot,
                                                  glyph_signal=share)
    return t.rows[keep], t.cols[keep], point_error_bound(
        rig, t.px_left[keep], t.px_right[keep], covs[0, keep], covs[1, keep])


def glyph_shares(renderer: Any, contacts: Any, nuisances: Any, seed: int,
                 frame_index: int) -> tuple[Any, Iterator[tuple[np.ndarray, int, np.ndarray,
                                                                  np.ndarray]]]:
    """A frame's linear signal and, lazily, every glyph's own share of it.

    Returns the full linear render (its truth names the glyphs) and an iterator of
    (selected glyphs (bool over the truth's), camera index 0 / 1, share, paper): ``share``
    is the signal with only every third row and column of glyphs printed minus ``paper``,
    the signal without any glyph (the image is linear in the print), so no other printed
    glyph lies within 1.5 spacings of a selected one.  Nine such renders cover every glyph.
    """
    def linear(ink: np.ndarray | None) -> Any:
        return renderer.render(contacts, nuisances, seed=seed, frame_index=frame_index,
                               ink_cells=ink, linear=True)

    rows, cols = renderer.artwork.rows, renderer.artwork.cols
    full = linear(None)
    t = full.truth

    def shares() -> Iterator[tuple[np.ndarray, int, np.ndarray, np.ndarray]]:
        blank = linear(np.zeros(rows * cols, bool))
        cell_row, cell_col = np.divmod(np.arange(rows * cols), cols)
        for a in range(3):
            for b in range(3):
                sel = (t.rows % 3 == a) & (t.cols % 3 == b)
                if not sel.any():
                    continue
                part = linear((cell_row % 3 == a) & (cell_col % 3 == b))
                yield sel, 0, part.left - blank.left, blank.left
                yield sel, 1, part.right - blank.right, blank.right

    return full, shares()


def _points(rig: Any, uv_left: np.ndarray, uv_right: np.ndarray) -> np.ndarray:
    """Triangulated (N, 3) points (the rig's reprojection errors are not needed here)."""
    return np.asarray(rig.triangulate(uv_left, uv_right)[0], np.float64)


def best_share_rmse(bounds_m2: np.ndarray, share: float) -> float:
    """RMSE bound (m) of the ``share`` of points with the smallest bounds.

    A decoder may drop points (coverage below 100 %), so the bound that matters for a
    coverage target is that of the best points it is allowed to keep.
    """
    b = np.sort(np.asarray(bounds_m2, np.float64).ravel())
    k = int(np.floor(float(share) * len(b)))
    if k <= 0:
        return float("nan")
    return float(np.sqrt(np.mean(b[:k])))
