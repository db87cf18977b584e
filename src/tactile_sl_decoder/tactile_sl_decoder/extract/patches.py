"""Glyph patches resampled from an image: every glyph at its own scale (no rclpy).

The extraction (:mod:`.extraction`), the grey centroid's background (:mod:`.centroid`) and
the stereo rescue (:mod:`tactile_sl_decoder.stereo.rescue`) sample their patches here.

Square patches (one scale per glyph, the sensor's case) come from a kernel that gives
``cv2.remap``'s bytes (bilinear, border replicated) at about 60 % of its time: a patch's
sample columns share their x positions and its rows their y positions, so each image row
it touches is interpolated along x once and used by two output rows.  The arithmetic is
OpenCV's (5.x, SIMD path): per sample ``p = fma(a, p01 - p00, p00)``, ``q = fma(a, p11 -
p10, p10)``, ``round(fma(b, q - p, p))`` in float32, rounded half to even, with a, b the
fractional parts of the sample position.  Whether it does give cv2.remap's bytes is checked
once per process on a fixed sample; where it does not (another OpenCV build or CPU path),
and for affine patches (tilted views), ``cv2.remap`` itself runs.
"""
from __future__ import annotations

import functools

import cv2
import numpy as np

from tactile_sl_decoder.contract import PATCH_SIZE
from tactile_sl_decoder.jit import fma32, kernel

_REMAP_MAX_ROWS = 32000  # cv2.remap wants maps smaller than SHRT_MAX rows


def sample_patches(gray: np.ndarray, u: np.ndarray, v: np.ndarray, step: np.ndarray,
                   size: int = PATCH_SIZE) -> np.ndarray:
    """(N, size, size) bilinear patches centred on (u, v) with ``step`` image px per patch px.

    ``step`` is (N,) (square patches) or (N, 2, 2): patch pixel (i, j) of glyph n is sampled
    at (u, v) + step[n] @ (x_j, y_i), the patch axes mapped by a local affine frame
    (:mod:`.perspective`: the lattice of a tilted view, de-skewed).  Outside the image the
    border pixel is repeated.
    """
    n = len(u)
    if n == 0:
        return np.zeros((0, size, size), np.uint8)
    if np.ndim(step) != 3 and gray.dtype == np.uint8 and gray.ndim == 2 and gray.size \
            and _kernel_is_exact():
        grid = (np.arange(size, dtype=np.float32) - (size - 1) / 2.0)
        offsets = grid * np.asarray(step, np.float32)[:, None]  # (n, size)
        uf = np.ascontiguousarray(u, np.float32)
        vf = np.ascontiguousarray(v, np.float32)
        if np.isfinite(offsets).all() and np.isfinite(uf).all() and np.isfinite(vf).all():
            image = np.ascontiguousarray(gray)
            return _square_patches(image.reshape(-1), image.shape[0], image.shape[1], uf, vf,
                                   np.ascontiguousarray(offsets)).reshape(n, size, size)
    return remap_patches(gray, u, v, step, size)


def remap_patches(gray: np.ndarray, u: np.ndarray, v: np.ndarray, step: np.ndarray,
                  size: int = PATCH_SIZE) -> np.ndarray:
    """:func:`sample_patches` through ``cv2.remap``: affine patches, the kernel's reference.

    The sampling maps have one row per patch, its samples in row-major order, so that the
    remapped image already is the (N, size, size) stack.
    """
    if len(u) == 0:
        return np.zeros((0, size, size), np.uint8)
    grid = (np.arange(size, dtype=np.float32) - (size - 1) / 2.0)
    if np.ndim(step) == 3:
        map_x, map_y = _affine_maps(u, v, np.asarray(step, np.float32), grid)
    else:
        # x varies along a patch row, y down a patch column: each map is one small (n, size)
        # array repeated, as a whole (x) or element by element (y), along the row
        offsets = grid * np.asarray(step, np.float32)[:, None]
        map_x = np.tile(np.asarray(u, np.float32)[:, None] + offsets, (1, size))
        map_y = np.repeat(np.asarray(v, np.float32)[:, None] + offsets, size, axis=1)
    return _remap(gray, map_x, map_y, size)


def _remap(gray: np.ndarray, map_x: np.ndarray, map_y: np.ndarray, size: int) -> np.ndarray:
    """cv2.remap over the maps (in chunks of rows OpenCV accepts) into an (N, size, size) stack."""
    n = len(map_x)
    out = np.empty((n, size * size), np.uint8)
    for start in range(0, n, _REMAP_MAX_ROWS):
        stop = min(n, start + _REMAP_MAX_ROWS)
        cv2.remap(gray, map_x[start:stop], map_y[start:stop], cv2.INTER_LINEAR,
                  dst=out[start:stop], borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(n, size, size)


def _affine_maps(u: np.ndarray, v: np.ndarray, frames: np.ndarray, grid: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Sampling maps (N, size*size) of patches whose axes are the columns of ``frames``."""
    size = len(grid)
    across = grid[None, :]                       # x_j, along a patch row
    down = np.repeat(grid, size)[None, :]        # y_i, row-major
    across = np.tile(across, (1, size))
    map_x = (np.asarray(u, np.float32)[:, None] + frames[:, 0, 0:1] * across
             + frames[:, 0, 1:2] * down)
    map_y = (np.asarray(v, np.float32)[:, None] + frames[:, 1, 0:1] * across
             + frames[:, 1, 1:2] * down)
    return map_x.astype(np.float32), map_y.astype(np.float32)


@functools.lru_cache(maxsize=1)
def _kernel_is_exact() -> bool:
    """Whether :func:`_square_patches` gives cv2.remap's bytes here, once per process.

    A fixed random sample, borders and positions on OpenCV's 1/64 grid (ties) included.
    """
    rng = np.random.default_rng(20261203)
    gray = rng.integers(0, 256, (37, 53), dtype=np.uint8)
    n = 400
    u = rng.uniform(-6.0, 59.0, n).astype(np.float32)
    v = rng.uniform(-6.0, 43.0, n).astype(np.float32)
    u[:100] = np.round(u[:100] * 64.0) / 64.0        # on the 1/64 grid: ties
    step = rng.uniform(0.2, 2.5, n).astype(np.float32)
    size = 9
    grid = (np.arange(size, dtype=np.float32) - (size - 1) / 2.0)
    offsets = np.ascontiguousarray(grid * step[:, None])
    mine = _square_patches(gray.reshape(-1), gray.shape[0], gray.shape[1], u, v, offsets)
    return bool(np.array_equal(mine.reshape(n, size, size),
                               remap_patches(gray, u, v, step, size)))


_SQUARE_SIGNATURE = ("uint8[:, ::1]({image}, int64, int64, float32[::1], float32[::1], "
                     "float32[:, ::1])")


@kernel([_SQUARE_SIGNATURE.format(image="uint8[::1]"),
         _SQUARE_SIGNATURE.format(image="Array(uint8, 1, 'C', readonly=True)")])
def _square_patches(flat: np.ndarray, height: int, width: int, u: np.ndarray, v: np.ndarray,
                    offsets: np.ndarray) -> np.ndarray:
    """(N, size*size) patches of the image ``flat`` (row-major, height x width).

    Sample (i, j) of patch k lies at (u[k] + offsets[k, j], v[k] + offsets[k, i]); each
    image row a patch touches is interpolated along x once (kept for the next output row,
    whose upper row it usually is).
    """
    n, size = offsets.shape
    out = np.empty((n, size * size), np.uint8)
    frac = np.empty(size, np.float32)
    left = np.empty(size, np.uint64)
    right = np.empty(size, np.uint64)
    upper = np.empty(size, np.float32)
    lower = np.empty(size, np.float32)
    for k in range(n):
        for j in range(size):
            x = u[k] + offsets[k, j]
            whole = np.floor(x)
            frac[j] = x - whole
            ix = int(whole)
            left[j] = min(max(ix, 0), width - 1)
            right[j] = min(max(ix + 1, 0), width - 1)
        lower_row = -1
        for i in range(size):
            y = v[k] + offsets[k, i]
            whole = np.floor(y)
            b = y - whole
            iy = int(whole)
            row0 = min(max(iy, 0), height - 1)
            row1 = min(max(iy + 1, 0), height - 1)
            if row0 == lower_row:
                for j in range(size):
                    upper[j] = lower[j]
            else:
                start = np.uint64(row0 * width)
                for j in range(size):
                    p0 = np.float32(flat[start + left[j]])
                    upper[j] = fma32(frac[j], np.float32(flat[start + right[j]]) - p0, p0)
            start = np.uint64(row1 * width)
            for j in range(size):
                p0 = np.float32(flat[start + left[j]])
                lower[j] = fma32(frac[j], np.float32(flat[start + right[j]]) - p0, p0)
            lower_row = row1
            base = i * size
            for j in range(size):
                top = upper[j]
                value = np.rint(fma32(b, lower[j] - top, top))
                out[k, base + j] = np.uint8(min(max(value, np.float32(0.0)), np.float32(255.0)))
    return out
