"""Glyph centres fitted with the printed artwork: the points' sub-pixel step (images path).

A glyph's grey-weighted centroid (:mod:`tactile_sl_decoder.extract.centroid`) needs no
knowledge of the print, but its threshold and window leave a bias that the image does not
carry: 0.006-0.012 px per axis on noise-free frames, a function of each glyph's shape, its
neighbours' ink, its sub-pixel phase and the lattice's perspective (docs/robustness.md,
"Where the clean rows' error comes from").  Once a glyph's cell is decoded, its whole
neighbourhood is known: the contract's artwork says what ink lies where around it.  This
module fits that artwork, as the camera sees it, to the image around each decoded glyph:

    I(p) = L(p) (a + b A(q(p - t)))

with A the artwork's albedo (1 pad, 0 ink) blurred by the camera's point-spread function,
q the map from image pixels to cell coordinates (the lattice of the glyph's decoded
neighbours: a quadratic in their cell offsets, fitted by least squares, so perspective,
lens distortion and the pad's stretch are followed to second order), t the glyph's centre
and L a plane of light (the light falls on ink and pad alike: a grey level is the light
times the reflectance, B. K. P. Horn, *Robot Vision*, MIT Press 1986, sec. 10.1).
Expanded, L (a + b A) is linear in six coefficients of 1, A, x, y, xA, yA; a small shift d
of the centre adds the artwork's derivative along it, b dA/dt . d (Gauss-Newton, linearised
at the current centre: Nocedal and Wright, *Numerical Optimization*, 2nd ed., 2006, sec.
10.3), so each pass is one weighted linear least-squares fit of eight unknowns per glyph,
batched over the glyphs; the shift is the derivative's coefficient over b's.  Pixels are
weighted by a Gaussian taper in cell units over a disc, the neighbours' ink inside the disc
being part of the model rather than a nuisance.

Pixels nearest a cell without a decoded glyph in this image are left out (a glyph whose ink
is gone or was not detected: the artwork's ink there is not in the image), and so is, from
the lattice map, a neighbour whose centroid lies off it (``map_outlier_px``: a worn glyph's).
A glyph keeps its centroid where the fit cannot be trusted: fewer than ``min_neighbours``
decoded neighbours within two cells, a lattice the quadratic does not follow (its residual
over ``max_map_residual_px`` and over ``map_residual_factor`` times the image's median: a
punch's edge, a fold), a window leaving the image, ink less than :data:`MIN_INK_CONTRAST`
of the pad's level deep, or a shift beyond ``max_shift_px``.  The fit draws on the rims of
the neighbours' ink as the lattice places them, information beyond the glyph's own that the
per-glyph Cramer-Rao bound of the sweep does not count.

Measured on the robustness sweep and the touch scenes: docs/robustness.md, "Centres fitted
with the artwork".  Each pass samples the blurred artwork three times per window pixel, so
the fit costs tens of milliseconds per image: it is off by default (``enabled``).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tactile_sl_common.settings import SettingsTable
from tactile_sl_decoder.pattern.artwork import render_array
from tactile_sl_decoder.pattern.fileio import Pattern

ARTWORK_PITCH_PX = 48.0
"""Resolution of the rendered artwork the fit samples, pixels per pitch."""
PIXEL_BOX_SIGMA = 0.2887
"""A camera pixel integrates the light over its square: a box of one pixel, whose standard
deviation 1 / sqrt(12) px adds in quadrature to the optics' blur."""
LATTICE_HALF = 2
"""The lattice map is fitted to the decoded neighbours within this many cells."""
MAP_OUTLIER_FACTOR = 3.0
"""A neighbour is off the lattice beyond this many times the image's median distance from
its quadratic (and beyond ``map_outlier_px``)."""
MIN_INK_CONTRAST = 0.2
"""The fitted ink's depth below the pad, as a fraction of the pad's level, that a fit needs
(a flat or a noise window gives none; at 0.05 a noise image still fitted some glyphs)."""
_BLOCK = 192
"""Glyphs per batch (bounds the window arrays to a few MB)."""


@dataclass
class ArtworkFitParams:
    """Settings of :func:`fit_centres` (module docstring)."""

    enabled: bool = False
    """Fit the decoded glyphs' centres with the artwork before triangulating (else the
    extraction's centroids are triangulated)."""
    blur_sigma_px: float = 0.8
    """The camera's blur, as a Gaussian's standard deviation in pixels (beside the pixel's
    own box)."""
    radius: float = 0.9
    """Radius of the pixels fitted around a glyph, in pitches."""
    taper: float = 0.6
    """Standard deviation of the Gaussian weight of those pixels, in pitches."""
    passes: int = 1
    """Fits per glyph, each linearised at the centre the one before found (a second moved the
    robustness sweep's realistic rows by 0.00-0.12 um, combined by 0.6 um, at twice the
    cost)."""
    max_map_residual_px: float = 0.1
    """A glyph whose neighbours depart from the lattice's quadratic by more than this (rms,
    px) and by more than map_residual_factor times the image's median departure keeps its
    centroid (a punch's edge, a fold)."""
    map_residual_factor: float = 5.0
    """See max_map_residual_px: the median departure is the centroids' own noise (harsh
    light raises it everywhere; a kink in the lattice only at its glyphs)."""
    map_outlier_px: float = 0.4
    """A neighbour whose centroid lies farther than this from the lattice's quadratic (and than
    3 x the image's median) is left out of it (a worn glyph's centroid; 0: none)."""
    max_shift_px: float = 0.5
    """A fit moving a centre farther than this from its centroid is not used."""
    min_neighbours: int = 9
    """Decoded lattice neighbours (glyph included, within two cells) a fit needs."""

    def validate(self) -> "ArtworkFitParams":
        """Raise ValueError naming the first setting outside :data:`ARTWORK_FIT_SETTINGS`."""
        ARTWORK_FIT_SETTINGS.check(self, "artwork_fit.")
        return self


ARTWORK_FIT_SETTINGS = SettingsTable(ArtworkFitParams, ranges={
    "blur_sigma_px": (0.0, 10.0), "radius": (0.3, 2.0), "taper": (0.1, 5.0), "passes": (1, 5),
    "max_map_residual_px": (0.0, 10.0), "map_residual_factor": (1.0, 100.0),
    "map_outlier_px": (0.0, 10.0), "max_shift_px": (0.0, 5.0),
    "min_neighbours": (6, 25)})
"""The decoder node's live ``artwork_fit.<field>`` parameters."""


class ArtworkModel:
    """The pattern's printed albedo at :data:`ARTWORK_PITCH_PX`, blurred as a camera sees it.

    ``pattern``: the contract pattern (its symbols and their glyph names); the artwork is
    rasterised exactly as ``tactile-sl pattern render`` draws it
    (:func:`tactile_sl_decoder.pattern.artwork.render_array`).
    """

    def __init__(self, pattern: Pattern, pitch_px: float = ARTWORK_PITCH_PX) -> None:
        top = int(pattern.array.max(initial=0))
        if top >= len(pattern.primitives):
            raise ValueError(f"artwork fit: a pattern of {len(pattern.primitives)} glyph names "
                             f"cannot draw symbols up to {top}")
        image, facts = render_array(pattern, pitch_px)
        self.albedo = image.astype(np.float32) / np.float32(255.0)
        self.cell00 = (float(facts["cell00_px"][0]), float(facts["cell00_px"][1]))
        self.pitch_px = float(facts["pitch_px"])
        self._blurred: dict[float, np.ndarray] = {}

    def blurred(self, sigma_tex: float) -> np.ndarray:
        """The albedo blurred by a Gaussian and its x and y derivatives: (H, W, 3) float32.

        ``sigma_tex`` in artwork pixels; the last few blurs are kept (a camera's scale and
        blur change rarely).  One image of three channels, so that one remap samples all.
        """
        key = round(float(sigma_tex), 2)
        found = self._blurred.get(key)
        if found is None:
            a = (cv2.GaussianBlur(self.albedo, (0, 0), key) if key > 0
                 else self.albedo)
            found = np.dstack([a, cv2.Sobel(a, cv2.CV_32F, 1, 0, ksize=3, scale=0.125),
                               cv2.Sobel(a, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)])
            if len(self._blurred) >= 4:
                self._blurred.pop(next(iter(self._blurred)))
            self._blurred[key] = found
        return found


def lattice_maps(uv: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                 half: int = LATTICE_HALF, outlier_px: float = 0.0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each glyph's local map from cell offsets to image pixels, fitted to its neighbours.

    ``uv`` (N, 2) px of glyphs at distinct cells ``rows``, ``cols``.  Per glyph, the decoded
    glyphs within ``half`` cells give p = c0 + J (dc, dr) + Q (dc^2, dr^2, dc dr) by least
    squares; with ``outlier_px`` > 0 the neighbours farther from it than that and than
    :data:`MAP_OUTLIER_FACTOR` times the median distance are left out and it is fitted
    again.  Returns J (N, 2, 2) px per cell (columns: along a row, i.e. per column step;
    per row step), Q (N, 2, 3), the fit's rms residual (N,) px and its point count (N,)
    (fewer than six: J and Q are not meaningful).
    """
    n = len(uv)
    shape = (int(rows.max()) + 1 + 2 * half, int(cols.max()) + 1 + 2 * half) if n else (1, 1)
    grid = np.full(shape, -1, np.int64)
    grid[rows + half, cols + half] = np.arange(n)
    offsets = np.array([(dr, dc) for dr in range(-half, half + 1)
                        for dc in range(-half, half + 1)], np.float64)
    neighbour = np.stack([grid[rows + half + int(dr), cols + half + int(dc)]
                          for dr, dc in offsets], axis=1)          # (N, K)
    dr, dc = offsets[:, 0], offsets[:, 1]
    basis = np.stack([np.ones_like(dc), dc, dr, dc * dc, dr * dr, dc * dr], axis=1)  # (K, 6)
    present = neighbour >= 0
    pos = uv[np.maximum(neighbour, 0)] * present[..., None]       # (N, K, 2)
    coef, resid = _quadratic_fit(basis, pos, present)
    if outlier_px > 0 and present.any():
        # a neighbour whose centroid lies off the lattice (a worn glyph's) is left out and
        # the quadratic fitted again
        off = np.hypot(resid[..., 0], resid[..., 1])
        limit = max(outlier_px, MAP_OUTLIER_FACTOR * float(np.median(off[present])))
        keep = present & (off <= limit)
        again = (keep.sum(axis=1) >= 6) & (keep != present).any(axis=1)
        if again.any():
            coef2, resid2 = _quadratic_fit(basis, pos, keep)
            coef[again], resid[again] = coef2[again], resid2[again]
            present = np.where(again[:, None], keep, present)
    count = present.sum(axis=1)
    rms = np.sqrt(np.sum(resid ** 2, axis=(1, 2)) / np.maximum(count - 6, 1))
    jac = np.transpose(coef[:, 1:3, :], (0, 2, 1))                 # (N, 2, 2): [axis, dc/dr]
    quad = np.transpose(coef[:, 3:6, :], (0, 2, 1))                # (N, 2, 3)
    return jac, quad, rms, count


def _quadratic_fit(basis: np.ndarray, pos: np.ndarray, use: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares quadratics of each glyph's neighbours: coefficients and residuals.

    ``basis`` (K, 6) at the K neighbour offsets, ``pos`` (N, K, 2) their positions, used
    where ``use`` (N, K); returns the coefficients (N, 6, 2) and the residuals (N, K, 2),
    zero where not used.
    """
    w = use.astype(np.float64)
    normal = np.einsum("nk,ka,kb->nab", w, basis, basis) + 1e-9 * np.eye(6)
    rhs = np.einsum("ka,nkc->nac", basis, pos * w[..., None])
    coef = np.linalg.solve(normal, rhs)
    return coef, (pos - np.einsum("ka,nac->nkc", basis, coef)) * w[..., None]


def fit_centres(gray: np.ndarray, uv: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                model: ArtworkModel, params: ArtworkFitParams
                ) -> tuple[np.ndarray, np.ndarray]:
    """Centres (N, 2) px of decoded glyphs fitted with the artwork, and which were (N,) bool.

    ``gray`` the image (H, W) uint8; ``uv`` (N, 2) the glyphs' centroids (raw pixels) at
    the distinct cells ``rows``, ``cols``.  A glyph not fitted keeps its ``uv``.
    """
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    rows = np.asarray(rows, np.int64)
    cols = np.asarray(cols, np.int64)
    out = uv.copy()
    fitted = np.zeros(len(uv), bool)
    if len(uv) < params.min_neighbours:
        return out, fitted
    jac, quad, map_rms, count = lattice_maps(uv, rows, cols,
                                             outlier_px=params.map_outlier_px)
    det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
    enough = (count >= params.min_neighbours) & (np.abs(det) > 1.0) & np.isfinite(det)
    if not enough.any():
        return out, fitted
    # a lattice the quadratic does not follow, beyond what the centroids' own noise gives
    limit = max(params.max_map_residual_px,
                params.map_residual_factor * float(np.median(map_rms[enough])))
    usable = enough & (map_rms <= limit)
    if not usable.any():
        return out, fitted
    scale = float(np.median(np.sqrt(np.abs(det[usable]))))        # px per pitch
    sigma_tex = float(np.hypot(params.blur_sigma_px, PIXEL_BOX_SIGMA)) / scale * model.pitch_px
    textures = model.blurred(sigma_tex)
    # the window's pixels: a disc of the fitted radius (in pixels, with a margin for the
    # lattice's stretch; the weight below is cut at the radius in cell units)
    half = int(np.ceil(params.radius * scale * 1.15))
    dy, dx = np.mgrid[-half:half + 1, -half:half + 1]
    disc = dx * dx + dy * dy <= half * half
    window = np.column_stack([dx[disc], dy[disc]]).astype(np.float32)
    index = np.flatnonzero(usable)
    # the cells decoded in this image (a border of one cell around them): pixels nearest a
    # cell without a glyph (ink gone, not detected) are not fitted, the artwork's ink there
    # being what the image lacks
    decoded = np.zeros((int(rows.max()) + 3, int(cols.max()) + 3), np.float32)
    decoded[rows + 1, cols + 1] = 1.0
    for first in range(0, len(index), _BLOCK):
        block = index[first:first + _BLOCK]
        centre, ok = _fit_block(gray, uv[block], rows[block], cols[block], jac[block],
                                quad[block], textures, model, window, scale, params, decoded)
        out[block[ok]] = centre[ok]
        fitted[block[ok]] = True
    return out, fitted


def _fit_block(gray: np.ndarray, uv: np.ndarray, rows: np.ndarray, cols: np.ndarray,
               jac: np.ndarray, quad: np.ndarray, textures: np.ndarray,
               model: ArtworkModel, window: np.ndarray, scale: float,
               params: ArtworkFitParams, decoded: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fit_centres` for one batch of usable glyphs: centres (n, 2), fitted (n,)."""
    h, w = gray.shape
    base = np.round(uv)
    px = (base[:, None, 0] + window[None, :, 0]).astype(np.float32)   # (n, P)
    py = (base[:, None, 1] + window[None, :, 1]).astype(np.float32)
    inside = (px >= 0) & (px <= w - 1) & (py >= 0) & (py <= h - 1)
    grey = gray[np.clip(py, 0, h - 1).astype(np.intp),
                np.clip(px, 0, w - 1).astype(np.intp)].astype(np.float32)
    inv = np.linalg.inv(jac).astype(np.float32)                    # (n, 2, 2): cell per px
    quad = quad.astype(np.float32)
    # artwork pixels per image pixel: d(texture)/d(cell) = pitch_px, times the inverse map
    to_texture = np.float32(model.pitch_px) * inv
    cell_col = cols[:, None].astype(np.float32)
    cell_row = rows[:, None].astype(np.float32)
    centre = uv.copy()
    ok = inside.mean(axis=1) >= 0.9
    for _ in range(params.passes):
        ex = px - centre[:, None, 0].astype(np.float32)
        ey = py - centre[:, None, 1].astype(np.float32)
        qc, qr = _cell_offsets(ex, ey, inv, quad)
        r2 = qc * qc + qr * qr
        weight = np.exp(np.float32(-0.5 / params.taper ** 2) * r2)
        weight *= (r2 <= np.float32(params.radius ** 2)) & inside
        # 1 where the nearest cell has a glyph decoded in this image (the border's cells: 0)
        weight *= cv2.remap(decoded, cell_col + qc + np.float32(1.0), cell_row + qr
                            + np.float32(1.0), cv2.INTER_NEAREST,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        sampled = _sample(textures, model, cell_col + qc, cell_row + qr)     # (n, P, 3)
        a, ax, ay = sampled[..., 0], sampled[..., 1], sampled[..., 2]
        # d A / d t: the artwork's gradient carried back through the map (a shift of the
        # centre moves every pixel's cell coordinates by -inv . t); one row per unknown
        design = np.empty((len(uv), 8) + a.shape[1:], np.float32)       # (n, 8, P)
        design[:, 0] = 1.0
        design[:, 1] = a
        np.multiply(ex, np.float32(1.0 / scale), out=design[:, 2])
        np.multiply(ey, np.float32(1.0 / scale), out=design[:, 3])
        np.multiply(design[:, 2], a, out=design[:, 4])
        np.multiply(design[:, 3], a, out=design[:, 5])
        design[:, 6] = -(ax * to_texture[:, None, 0, 0] + ay * to_texture[:, None, 1, 0])
        design[:, 7] = -(ax * to_texture[:, None, 0, 1] + ay * to_texture[:, None, 1, 1])
        weighted = design * weight[:, None, :]                         # (n, 8, P)
        normal = np.matmul(weighted, design.transpose(0, 2, 1)).astype(np.float64)
        rhs = np.matmul(weighted, grey[..., None])[..., 0].astype(np.float64)
        normal += 1e-9 * np.eye(8) * np.maximum(
            np.trace(normal, axis1=1, axis2=2), 1.0)[:, None, None]
        try:
            coef = np.linalg.solve(normal, rhs[..., None])[..., 0]
        except np.linalg.LinAlgError:
            return centre, np.zeros(len(uv), bool)
        contrast = coef[:, 1]
        # the ink must stand out of the pad: depth b over the pad's level a + b (a flat or
        # inverted window gives no position, whatever its least-squares shift)
        pad = coef[:, 0] + contrast
        good = np.isfinite(coef).all(axis=1) & (contrast > MIN_INK_CONTRAST * np.abs(pad))
        shift = np.where(good[:, None], coef[:, 6:8] / np.where(good, contrast, 1.0)[:, None],
                         0.0)
        centre = centre + np.clip(shift, -1.0, 1.0)
        ok &= good
    moved = np.hypot(centre[:, 0] - uv[:, 0], centre[:, 1] - uv[:, 1])
    ok &= np.isfinite(moved) & (moved <= params.max_shift_px)
    return centre, ok


def _cell_offsets(ex: np.ndarray, ey: np.ndarray, inv: np.ndarray, quad: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Cell offsets (dc, dr) of pixel offsets (ex, ey) from a glyph's centre.

    Inverts p = J q + Q (dc^2, dr^2, dc dr) by a fixed-point step from q = J^-1 p (the
    quadratic term is a small correction over a window of one cell).
    """
    qc = inv[:, None, 0, 0] * ex + inv[:, None, 0, 1] * ey
    qr = inv[:, None, 1, 0] * ex + inv[:, None, 1, 1] * ey
    cc, rr, cr = qc * qc, qr * qr, qc * qr
    sx = ex - (quad[:, None, 0, 0] * cc + quad[:, None, 0, 1] * rr + quad[:, None, 0, 2] * cr)
    sy = ey - (quad[:, None, 1, 0] * cc + quad[:, None, 1, 1] * rr + quad[:, None, 1, 2] * cr)
    return (inv[:, None, 0, 0] * sx + inv[:, None, 0, 1] * sy,
            inv[:, None, 1, 0] * sx + inv[:, None, 1, 1] * sy)


def _sample(textures: np.ndarray, model: ArtworkModel, col: np.ndarray,
            row: np.ndarray) -> np.ndarray:
    """The blurred albedo and its derivatives at cell coordinates (bilinear): (..., 3)."""
    x = np.float32(model.cell00[0]) + col * np.float32(model.pitch_px)
    y = np.float32(model.cell00[1]) + row * np.float32(model.pitch_px)
    out: np.ndarray = cv2.remap(textures, x, y, cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REPLICATE)
    return out
