"""Grey-weighted glyph centres of resampled patches (the extraction's sub-pixel step).

A binary region's centroid is quantised by the threshold; the grey-weighted centroid of the
glyph's patch is several times more precise under blur. Its weights start at a threshold
that follows the patch's background (a plane through its border pixels, or, at an object's
rim, the grey closing of the image), so that uneven light or a dark object beside the glyph
does not pull the centre aside. Vectorised over all patches: thin matrix products, no loop
over glyphs.
"""
from __future__ import annotations

import functools
from typing import Callable

import cv2
import numpy as np

from tactile_sl_decoder.extract.patches import sample_patches
from tactile_sl_decoder.jit import fma32, kernel

_MOMENT_BLOCK = 256  # patches per product in patch_centroid_offset
RELATIVE_ONE = 256
"""A pixel's centroid weight is its depth below the threshold over the threshold, in steps
of 1/RELATIVE_ONE (integers, so that the kernel and numpy sum them exactly)."""
_MIN_DIVISOR = 16
"""Thresholds below this many grey levels divide as this one (a black patch: no light to
normalise by); it bounds a weight by 255 * RELATIVE_ONE / 16 and keeps the moments exact."""
_MAX_WEIGHT = 255 * RELATIVE_ONE // _MIN_DIVISOR + 1
_SHIFT = 16
_HALF = 1 << (_SHIFT - 1)
_RECIPROCALS = np.array([round(RELATIVE_ONE * (1 << _SHIFT) / max(t, _MIN_DIVISOR))
                         for t in range(256)], np.int64)
"""RELATIVE_ONE / threshold in fixed point: weight * it, rounded, is the weight over the
threshold (a product and a shift instead of a division, the same integers in numba and
numpy)."""
CLOSING_SPACINGS = 0.75
"""Side of the square grey closing that estimates the background under glyphs, in glyph
spacings: wider than a glyph (removed), narrower than an object's dark area (kept)."""

BackgroundPatches = Callable[[np.ndarray], np.ndarray]
"""Patch indices -> (len, size, size) uint8 background patches at those patches' places."""


def patch_centroid_offset(patches: np.ndarray, dark: bool = True, radius: float = 0.45,
                          flatten: bool = False, level: float = 0.5,
                          tolerance: float = 0.15, background: BackgroundPatches | None = None,
                          background_step: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Grey-weighted centroid of each patch's central disc, in patch pixels from its centre.

    Weights are how much darker (or brighter) than the patch mean a pixel is, inside a disc
    of ``radius`` patch sides, which holds the glyph but not its neighbours, *over the
    threshold there*: the light falls on ink and pad alike, so a pixel's grey level is the
    illumination times the print's reflectance, and a glyph's depth below its threshold
    scales with the light at that pixel.  Unnormalised weights lean the centre towards the
    brighter side by the gradient of log-illumination times the glyph's second moment
    (B. K. P. Horn, *Robot Vision*, MIT Press 1986, sec. 10.1, image irradiance as
    illumination times reflectance); over the threshold they are the reflectance's
    (:data:`RELATIVE_ONE`).  Measured on the simulator's images (noise-free, the shipped rig's
    fall-off of the light across the field): the glyph's own image share is centred 0.011 /
    0.006 px rms (u / v) off its projected cell centre, 0.004 / 0.003 px as reflectance; the
    decoder's centres against the truth 0.0154 / 0.0119 -> 0.0087 / 0.0090 px; on the
    robustness sweep every row's 3-D RMSE drops (object_dark realistic 6.98 -> 4.66 um, dust
    severe 4.96 -> 3.65 um, clean rows 2.57 -> 2.51 um: the bias was shared by both cameras,
    so most of it had cancelled in the disparity; docs/robustness.md).

    With ``flatten`` the weights instead start at a tilted plane: the least-squares plane
    through the patch's border pixels (at a patch span of one spacing they lie in the gaps
    between glyphs: the local background), lowered to ``level`` of the way from the patch
    mean (0) to the background at the centre (1), so max(plane - grey, 0).  A centre of
    gravity is biased towards the darker side of a background that is not flat (B. F.
    Alexander and K. C. Ng, "Elimination of systematic error in subpixel accuracy centroid
    estimation", Optical Engineering 30(9), 1991, on threshold and background): under an
    illumination gradient, a shadow's rim or a hot spot, a flat threshold takes in more of
    the glyph's blurred edge (and of the background) on the dark side; a threshold parallel
    to the background cuts the edge at the same relative depth all round.  ``level`` 0.5
    rather than 0 counts more of each edge, where the position information is (sweep,
    realistic lighting / exposure 3-D RMSE, measured before the misfit test below: 0.0101
    mm / - at 0, 0.0098 / 0.0031 at 0.2, 0.0097 / 0.0028 at 0.35, 0.0097 / 0.0026 at 0.5,
    0.0098 / 0.0026 at 0.65; flat mean 0.0103 / 0.0033; at 1 the background's noise comes in
    and 2-D errors grow again).  A patch whose border strays from its plane by more than
    ``tolerance`` times the plane's level (rms; set above sensor noise and a neighbour's
    blurred edge, tuned on the sweep: 0.1 and 0.15 alike, 0.2 lets object_text rise to
    0.0103 mm) has a background that is no plane, e.g. an object's texture seen through the
    pad: a plane fit to it would tilt the threshold at random (realistic object_text 0.0096
    -> 0.0105 mm without this test), so that patch keeps the flat mean threshold.

    With ``background`` (patch indices -> background patches, the grey closing of the image
    over :data:`CLOSING_SPACINGS`: glyphs removed, an object's dark area kept), such a patch
    whose background steps across it by more than ``background_step`` of its mean (max - min;
    the rim of a dark object, not a fine texture) takes its threshold from that background
    instead, scaled to the same start level: a flat mean there counts the object's dark side
    as ink and pulls the centre onto it (sweep, object_dark mild / realistic / severe 3-D
    RMSE 0.0064 / 0.0096 / 0.0084 -> 0.0046 / 0.0070 / 0.0079 mm; at a step of 0.3 the
    striped object improved too but object_text realistic / severe rose 0.0001 / 0.0002 mm;
    applied to every misfit patch, object_text realistic 0.0094 -> 0.0103 mm).
    """
    n, size = patches.shape[0], patches.shape[1]
    flat = np.ascontiguousarray(patches.reshape(n, size * size))
    kernels = _centroid_kernels(size, radius)
    if flatten:
        if _planes_kernel_is_exact():
            ring, _, basis = _border_plane(size)
            thresh, misfit, mean = _plane_thresholds(
                flat, ring, _border_products(size), basis, np.float32(level),
                np.float32(1.0 - level), np.float32(tolerance))
            if background is not None and misfit.any():
                _background_thresholds(thresh, misfit, mean, background, level,
                                       background_step)
        else:
            thresh = _threshold_planes(flat, size, level, tolerance, background,
                                       background_step)
    else:
        # the (rounded) patch mean, repeated over the patch
        thresh = np.repeat(cv2.reduce(flat, 1, cv2.REDUCE_AVG, dtype=cv2.CV_8U), size * size,
                           axis=1)
    doubled = _doubled_kernels(size, radius)
    if doubled is None:
        return _grey_moments_reference(flat, thresh, kernels, dark)
    return _grey_moments(flat, thresh, doubled, bool(dark), _RECIPROCALS)


def _grey_moments_reference(flat: np.ndarray, thresh: np.ndarray, kernels: np.ndarray,
                            dark: bool) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_grey_moments` in numpy (its tests' reference): weights, thin products."""
    n = len(flat)
    # uint8 arithmetic: the saturating difference is exactly max(threshold - grey, 0) (or
    # max(grey - threshold, 0)); then over the threshold, in 1/RELATIVE_ONE steps rounded
    # to nearest (integers: the same bits as the kernel's)
    weight = cv2.subtract(thresh, flat) if dark else cv2.subtract(flat, thresh)
    weight = ((weight.astype(np.int64) * _RECIPROCALS[thresh] + _HALF) >> _SHIFT
              ).astype(np.float32)
    moments = np.empty((n, 3), np.float32)
    for first in range(0, n, _MOMENT_BLOCK):
        np.matmul(weight[first:first + _MOMENT_BLOCK], kernels,
                  out=moments[first:first + _MOMENT_BLOCK])
    total = np.maximum(moments[:, 0], 1e-6)
    return moments[:, 1] / total, moments[:, 2] / total


@kernel("Tuple((float32[::1], float32[::1]))(uint8[:, ::1], uint8[:, ::1], int32[:, ::1], "
        "boolean, int64[::1])")
def _grey_moments(flat: np.ndarray, thresh: np.ndarray, doubled: np.ndarray, dark: bool,
                  reciprocals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grey-weighted centroid (du, dv) of each patch, one pass per patch.

    Weights are max(threshold - grey, 0) (``dark``; else max(grey - threshold, 0)) over the
    threshold (in 1/:data:`RELATIVE_ONE` steps, rounded) times the disc kernels.

    ``doubled`` is (3, pixels): twice the disc kernels, integers (:func:`_doubled_kernels`).
    The moments are sums of integers below 2^24, exact in int32 and in float32 alike, so
    they are summed as integers (in any order, vectorised) and give the float32 matrix
    product's bits.
    """
    n, pixels = flat.shape
    du = np.empty(n, np.float32)
    dv = np.empty(n, np.float32)
    floor = np.float32(1e-6)
    half = np.float32(0.5)
    for i in range(n):
        m0 = 0
        m1 = 0
        m2 = 0
        for p in range(pixels):
            t = np.int32(thresh[i, p])
            if dark:
                w = t - np.int32(flat[i, p])
            else:
                w = np.int32(flat[i, p]) - t
            if w <= 0:
                continue
            w = (w * reciprocals[t] + _HALF) >> _SHIFT
            m0 += w * doubled[0, p]
            m1 += w * doubled[1, p]
            m2 += w * doubled[2, p]
        total = max(np.float32(m0) * half, floor)
        du[i] = np.float32(m1) * half / total
        dv[i] = np.float32(m2) * half / total
    return du, dv


@functools.lru_cache(maxsize=8)
def _doubled_kernels(size: int, radius: float) -> np.ndarray | None:
    """(3, size*size) int32: twice :func:`_centroid_kernels`, or None where not exact.

    Pixel coordinates from the patch centre are whole or half numbers; None where a patch's
    moments could leave float32's exact integers (a large patch), so that
    :func:`_grey_moments` would not give the matrix product's bits.
    """
    doubled = 2.0 * _centroid_kernels(size, radius).T.astype(np.float64)
    if not np.array_equal(doubled, np.round(doubled)) or \
            _MAX_WEIGHT * np.abs(doubled).sum(axis=1).max() >= 2.0 ** 24:
        return None
    return np.ascontiguousarray(doubled, np.int32)


@kernel("Tuple((uint8[:, ::1], boolean[::1], float32[::1]))(uint8[:, ::1], int64[::1], "
        "float32[:, ::1], float32[:, ::1], float32, float32, float32)")
def _plane_thresholds(flat: np.ndarray, ring: np.ndarray, both: np.ndarray, basis: np.ndarray,
                      level: np.float32, rest: np.float32, tolerance: np.float32
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_threshold_planes` without the background step: thresholds, misfit, mean.

    The same float32 operations in the same order: OpenBLAS's thin products here are
    sequential fused multiply-adds over the inner index, ``cv2.reduce``'s average the exact
    integer sum times float32(1 / pixels), ``convertScaleAbs`` a rounding half to even with
    saturation (``rest`` is float32(1 - level)).
    """
    n, pixels = flat.shape
    r = len(ring)
    thresh = np.empty((n, pixels), np.uint8)
    misfit = np.empty(n, np.bool_)
    mean = np.empty(n, np.float32)
    inv_pixels = np.float32(1.0 / pixels)
    count = np.float32(r)
    one = np.float32(1.0)
    zero = np.float32(0.0)
    for i in range(n):
        c0 = zero
        c1 = zero
        c2 = zero
        a0 = zero
        a1 = zero
        a2 = zero
        squares = 0
        for t in range(r):
            g = int(flat[i, ring[t]])
            squares += g * g                       # integers below 2^24: exact in float32
            b = np.float32(g)
            c0 = fma32(b, both[t, 0], c0)
            c1 = fma32(b, both[t, 1], c1)
            c2 = fma32(b, both[t, 2], c2)
            a0 = fma32(b, both[t, 3], a0)
            a1 = fma32(b, both[t, 4], a1)
            a2 = fma32(b, both[t, 5], a2)
        dot = zero
        dot += a0 * c0
        dot += a1 * c1
        dot += a2 * c2
        resid = np.float32(squares) - dot
        bound = tolerance * c0
        bad = resid > bound * bound * count
        total = 0
        for p in range(pixels):
            total += int(flat[i, p])               # integers below 2^24: exact in float32
        m = np.float32(total) * inv_pixels
        start = m if bad else rest * m + level * c0
        scale = start / max(c0, one)
        k0 = c0 * scale
        k1 = zero if bad else c1 * scale
        k2 = zero if bad else c2 * scale
        for p in range(pixels):
            x = fma32(k2, basis[2, p], fma32(k1, basis[1, p], fma32(k0, basis[0, p], zero)))
            x = np.rint(abs(x))
            thresh[i, p] = np.uint8(255.0 if x > 255.0 else x)
        misfit[i] = bad
        mean[i] = m
    return thresh, misfit, mean


@functools.cache
def _planes_kernel_is_exact() -> bool:
    """Whether :func:`_plane_thresholds` gives :func:`_threshold_planes`' bytes here.

    Once per process (BLAS and OpenCV builds differ), on random patches of several batch
    sizes, smooth and noisy, two patch sizes.
    """
    rng = np.random.default_rng(20261204)
    for size, n in ((18, 300), (18, 7), (18, 1), (12, 64)):
        g = np.arange(size, dtype=np.float32) - (size - 1) / 2.0
        ramp = (rng.uniform(-6, 6, (n, 1, 1)) * g[None, :, None]
                + rng.uniform(-6, 6, (n, 1, 1)) * g[None, None, :])
        base = rng.uniform(20, 235, (n, 1, 1)) + ramp
        noisy = rng.normal(0.0, rng.uniform(0, 40, (n, 1, 1)), (n, size, size))
        flat = np.clip(base + noisy, 0, 255).astype(np.uint8).reshape(n, size * size)
        ring, _, basis = _border_plane(size)
        for level, tolerance in ((0.5, 0.15), (0.2, 0.05)):
            mine = _plane_thresholds(flat, ring, _border_products(size), basis,
                                     np.float32(level), np.float32(1.0 - level),
                                     np.float32(tolerance))[0]
            if not np.array_equal(mine, _threshold_planes(flat, size, level, tolerance)):
                return False
    return True


def _threshold_planes(flat: np.ndarray, size: int, level: float, tolerance: float,
                      background: BackgroundPatches | None = None,
                      background_step: float = 0.5) -> np.ndarray:
    """(n, size*size) uint8 thresholds of :func:`patch_centroid_offset` with ``flatten``.

    In numpy: the reference of :func:`_plane_thresholds`, and its fallback.

    Per patch the least-squares plane a + b x + c y through the border pixels and its
    residual (||r||^2 = ||v||^2 - (A^T v) . coef for the least-squares coef of values v,
    one product for both), the start level between the mean and a, the plane scaled to it
    (flat at the mean where the border is no plane), evaluated at every pixel.
    """
    n = len(flat)
    ring, fit, basis = _border_plane(size)
    both = _border_products(size)
    coef = np.empty((n, 3), np.float32)
    misfit = np.empty(n, bool)
    for first in range(0, n, _MOMENT_BLOCK):
        border = flat[first:first + _MOMENT_BLOCK, ring].astype(np.float32)
        prod = border @ both                                 # coef | A^T v
        c = prod[:, :3]
        resid = np.einsum("ij,ij->i", border, border) - np.einsum("ij,ij->i", prod[:, 3:], c)
        coef[first:first + _MOMENT_BLOCK] = c
        misfit[first:first + _MOMENT_BLOCK] = resid > (tolerance * c[:, 0]) ** 2 * len(ring)
    mean = cv2.reduce(flat, 1, cv2.REDUCE_AVG, dtype=cv2.CV_32F)[:, 0]
    back = coef[:, 0]
    start = np.where(misfit, mean, (1.0 - level) * mean + level * back)
    coef *= (start / np.maximum(back, 1.0))[:, None]
    coef[misfit, 1:] = 0.0
    thresh = np.empty(flat.shape, np.uint8)
    for first in range(0, n, _MOMENT_BLOCK):
        # rounded, saturated to 0..255 (abs: only a border far from any plane, which the
        # misfit test flattens, could take the plane below 0)
        thresh[first:first + _MOMENT_BLOCK] = cv2.convertScaleAbs(
            coef[first:first + _MOMENT_BLOCK] @ basis)
    if background is not None and misfit.any():
        _background_thresholds(thresh, misfit, mean, background, level, background_step)
    return thresh


def _background_thresholds(thresh: np.ndarray, misfit: np.ndarray, mean: np.ndarray,
                           background: BackgroundPatches, level: float,
                           background_step: float) -> None:
    """Misfit patches whose background steps across them take their thresholds from it.

    In place; see :func:`patch_centroid_offset`.
    """
    idx = np.flatnonzero(misfit)
    back = background(idx).reshape(len(idx), -1).astype(np.float32)
    back_mean = np.maximum(back.mean(axis=1), 1.0)
    stepped = (back.max(axis=1) - back.min(axis=1)) / back_mean > background_step
    if stepped.any():
        idx, back = idx[stepped], back[stepped]
        # the same start level as the plane's: (1 - level) mean + level background
        scale = (1.0 - level) * mean[idx] / back_mean[stepped] + level
        thresh[idx] = np.clip(back * scale[:, None] + 0.5, 0, 255).astype(np.uint8)


def closing_background(gray: np.ndarray, u: np.ndarray, v: np.ndarray, step: np.ndarray,
                       size: int, spacing: float) -> BackgroundPatches:
    """Background patches at glyph centres (u, v), computed only for the patches asked for.

    The grey closing (dilation then erosion with a square of :data:`CLOSING_SPACINGS`
    spacings; R. C. Gonzalez and R. E. Woods, Digital Image Processing, 3rd ed., sec. 9.6.1)
    of the smallest image region holding those patches plus the closing's reach (so it equals
    the whole image's closing there), resampled like the patches themselves.
    """
    side = int(2 * round(CLOSING_SPACINGS * max(spacing, 1.0) / 2) + 1)

    def patches_at(idx: np.ndarray) -> np.ndarray:
        pu, pv, ps = u[idx], v[idx], step[idx]
        reach = np.abs(ps).sum(axis=2).max(axis=1) if ps.ndim == 3 else ps
        half = reach * (size / 2.0) + 2.0
        h, w = gray.shape
        x0 = max(0, int(np.floor(np.min(pu - half))) - side)
        y0 = max(0, int(np.floor(np.min(pv - half))) - side)
        x1 = min(w, int(np.ceil(np.max(pu + half))) + side + 1)
        y1 = min(h, int(np.ceil(np.max(pv + half))) + side + 1)
        closed = cv2.morphologyEx(np.ascontiguousarray(gray[y0:y1, x0:x1]), cv2.MORPH_CLOSE,
                                  cv2.getStructuringElement(cv2.MORPH_RECT, (side, side)))
        return sample_patches(closed, pu - x0, pv - y0, ps, size)

    return patches_at


@functools.lru_cache(maxsize=8)
def _border_products(size: int) -> np.ndarray:
    """(R, 6): the plane fit of :func:`_border_plane` and its design matrix A side by side."""
    ring, fit, basis = _border_plane(size)
    return np.ascontiguousarray(np.concatenate([fit, basis[:, ring].T], axis=1))


@functools.lru_cache(maxsize=8)
def _border_plane(size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Border pixels of a size x size patch and a plane a + b x + c y fitted to them.

    Returns their flat indices, the (R, 3) transposed pseudo-inverse of their design matrix
    (values @ fit = least-squares a, b, c) and the (3, size*size) basis that evaluates the
    plane at every pixel (x, y from the patch centre).
    """
    g = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    gx = np.broadcast_to(g[None, :], (size, size)).reshape(-1)
    gy = np.broadcast_to(g[:, None], (size, size)).reshape(-1)
    ring = np.flatnonzero(np.maximum(np.abs(gx), np.abs(gy)) > (size - 1) / 2.0 - 1.0)
    design = np.stack([np.ones(len(ring)), gx[ring], gy[ring]], axis=1)
    fit = np.ascontiguousarray(np.linalg.pinv(design).T, np.float32)
    basis = np.ascontiguousarray(np.stack([np.ones_like(gx), gx, gy]), np.float32)
    return ring, fit, basis


@functools.lru_cache(maxsize=8)
def _centroid_kernels(size: int, radius: float) -> np.ndarray:
    """(size*size, 3) disc mask, disc * x and disc * y, for patch_centroid_offset."""
    g = np.arange(size, dtype=np.float32) - (size - 1) / 2.0
    gx = np.broadcast_to(g[None, :], (size, size)).reshape(-1)
    gy = np.broadcast_to(g[:, None], (size, size)).reshape(-1)
    disc = ((gx * gx + gy * gy) <= (radius * size) ** 2).astype(np.float32)
    return np.ascontiguousarray(np.stack([disc, disc * gx, disc * gy], axis=1))
