"""Glyph scale and lattice shape that vary across the image: strongly tilted views (no rclpy).

A flat print tilted by 40 deg at 16 mm from the cameras is seen with glyphs 2-3 times larger
(in side) at its near end than at its far end, and foreshortened along the tilt: the
lattice is anisotropic (cos 40 = 0.77 along one axis) and, by perspective, keystoned.  The
extraction's relative gates (region area against *the* typical glyph, patch size from a
local spacing clipped around *the* median spacing) assume one scale.  Here:

* :func:`typical_area_field` -- the typical glyph area as a smooth function of the image
  position: a least-squares quadratic in (u, v) of log(area), refit twice without the
  regions more than 0.35 (a factor 1.4) off it (linked pairs, noise).  Under a pinhole
  camera a plane's magnification is 1 / depth, depth being affine in the image
  coordinates of a plane (z = d / (n . K^-1 x)); log(area) of a glyph is then
  -3 log(n . K^-1 x) + const (area ~ 1/z^2 times the foreshortening 1/z of the normal's
  component; Hartley & Zisserman, Multiple View Geometry, 2nd ed., sec. 8.1 and A7), smooth and
  well approximated by a quadratic across one image.
* :func:`lattice_frames` -- per glyph a symmetric 2x2 frame S with S S^T = A A^T, A = [a b]
  being the local lattice basis (column and row steps): from the four nearest neighbours'
  displacements d_k, sum_k d_k d_k^T = 2 (a a^T + b b^T) for a lattice point with its four
  edge neighbours, so S = sqrtm(sum / 2).  S = A Q with Q a rotation: sampling a patch
  through S removes the lattice's anisotropy (foreshortening) without turning the glyph
  (Q = I for a lattice aligned with the image axes; for an isotropic lattice S = s I, the
  isotropic patch as before).  The entries are then smoothed by the median over each glyph
  and its four nearest neighbours (a stray detection spoils one frame, not its patch).

These engage only where the scale or the anisotropy is clearly not uniform
(``ExtractionParams.perspective`` and its thresholds): the sensor's own images, with a
near-uniform lattice, are extracted exactly as before.
"""
from __future__ import annotations

import numpy as np

from tactile_sl_decoder.neighbours import knn_within

_TRIM_LOG = 0.35     # regions more than a factor e^0.35 = 1.4 off the fit are left out of it


def _quadratic_terms(u: np.ndarray, v: np.ndarray, centre: tuple[float, float],
                     scale: float) -> np.ndarray:
    x = (np.asarray(u, np.float64) - centre[0]) / scale
    y = (np.asarray(v, np.float64) - centre[1]) / scale
    return np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])


class AreaField:
    """Typical glyph area as a function of the image position (see module docstring)."""

    def __init__(self, coefficients: np.ndarray, centre: tuple[float, float],
                 scale: float) -> None:
        self.coefficients = coefficients
        self.centre = centre
        self.scale = scale

    def __call__(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Typical area (px^2) at the image points (u, v)."""
        return np.exp(_quadratic_terms(u, v, self.centre, self.scale) @ self.coefficients)


def typical_area_field(u: np.ndarray, v: np.ndarray, area: np.ndarray,
                       rounds: int = 2) -> AreaField | None:
    """Robust quadratic fit of log(area) over the image (None for fewer than 12 regions)."""
    n = len(u)
    if n < 12:
        return None
    centre = (float(np.mean(u)), float(np.mean(v)))
    scale = float(max(np.ptp(u), np.ptp(v), 1.0))
    terms = _quadratic_terms(u, v, centre, scale)
    log_area = np.log(np.maximum(np.asarray(area, np.float64), 1.0))
    use = np.ones(n, bool)
    coefficients = np.zeros(6)
    for _ in range(rounds + 1):
        if use.sum() < 12:
            return None
        coefficients = np.linalg.lstsq(terms[use], log_area[use], rcond=None)[0]
        use = np.abs(terms @ coefficients - log_area) < _TRIM_LOG
    return AreaField(coefficients, centre, scale)


def lattice_frames(u: np.ndarray, v: np.ndarray, search_px: float) -> np.ndarray:
    """(N, 2, 2) symmetric local lattice frames (px per lattice step), see module docstring.

    Glyphs with fewer than four neighbours within ``search_px`` get the median frame of
    those that have four.
    """
    x = np.ascontiguousarray(u, np.float64)
    y = np.ascontiguousarray(v, np.float64)
    n = len(x)
    frames = np.zeros((n, 2, 2))
    if n < 5:
        return frames
    dist, idx = knn_within(x, y, 5, float(search_px))
    near = idx[:, 1:5]
    complete = np.isfinite(dist[:, 4])
    safe = np.where(complete[:, None], near, 0)
    du = x[safe] - x[:, None]
    dv = y[safe] - y[:, None]
    # half the second moment of the four steps: a a^T + b b^T
    sxx = 0.5 * (du * du).sum(axis=1)
    sxy = 0.5 * (du * dv).sum(axis=1)
    syy = 0.5 * (dv * dv).sum(axis=1)
    moments = np.column_stack([sxx, sxy, syy])
    if not complete.any():
        return frames
    fallback = np.median(moments[complete], axis=0)
    moments[~complete] = fallback
    # median over the glyph and its four nearest neighbours, entry by entry
    stack = np.concatenate([moments[:, None, :], moments[safe]], axis=1)
    stack[~complete, 1:] = moments[~complete, None, :]
    moments = np.median(stack, axis=1)
    return symmetric_sqrt(moments[:, 0], moments[:, 1], moments[:, 2])


def symmetric_sqrt(sxx: np.ndarray, sxy: np.ndarray, syy: np.ndarray) -> np.ndarray:
    """(N, 2, 2) principal square roots of the symmetric positive semi-definite matrices.

    For a 2x2 SPD matrix M, sqrt(M) = (M + sqrt(det M) I) / sqrt(tr M + 2 sqrt(det M))
    (Cayley-Hamilton; Levinger, "The square root of a 2x2 matrix", Math. Mag. 53(4), 1980).
    """
    det = np.sqrt(np.maximum(sxx * syy - sxy * sxy, 0.0))
    norm = np.sqrt(np.maximum(sxx + syy + 2.0 * det, 1e-12))
    out = np.empty((len(sxx), 2, 2))
    out[:, 0, 0] = (sxx + det) / norm
    out[:, 0, 1] = out[:, 1, 0] = sxy / norm
    out[:, 1, 1] = (syy + det) / norm
    return out


def anisotropy(frames: np.ndarray) -> np.ndarray:
    """Ratio of the larger to the smaller singular value of each frame (1 = isotropic)."""
    a, b, c = frames[:, 0, 0], frames[:, 0, 1], frames[:, 1, 1]
    half_trace = 0.5 * (a + c)
    radius = np.sqrt(0.25 * (a - c) ** 2 + b * b)
    return (half_trace + radius) / np.maximum(half_trace - radius, 1e-9)
