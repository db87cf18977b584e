"""Glyph patches resampled from an image: every glyph at its own scale, in one remap (no rclpy).

The extraction (:mod:`.extraction`), the grey centroid's background (:mod:`.centroid`) and
the stereo rescue (:mod:`tactile_sl_decoder.stereo.rescue`) sample their patches here.
"""
from __future__ import annotations

import cv2
import numpy as np

from tactile_sl_decoder.contract import PATCH_SIZE

_REMAP_MAX_ROWS = 32000  # cv2.remap wants maps smaller than SHRT_MAX rows


def sample_patches(gray: np.ndarray, u: np.ndarray, v: np.ndarray, step: np.ndarray,
                   size: int = PATCH_SIZE) -> np.ndarray:
    """(N, size, size) bilinear patches centred on (u, v) with ``step`` image px per patch px.

    ``step`` is (N,) (square patches) or (N, 2, 2): patch pixel (i, j) of glyph n is sampled
    at (u, v) + step[n] @ (x_j, y_i), the patch axes mapped by a local affine frame
    (:mod:`.perspective`: the lattice of a tilted view, de-skewed).

    One cv2.remap over a sampling map with one row per patch (its size*size samples in
    row-major order), so that the remapped image already is the (N, size, size) stack;
    outside the image the border pixel is repeated.
    """
    n = len(u)
    if n == 0:
        return np.zeros((0, size, size), np.uint8)
    grid = (np.arange(size, dtype=np.float32) - (size - 1) / 2.0)
    if np.ndim(step) == 3:
        map_x, map_y = _affine_maps(u, v, np.asarray(step, np.float32), grid)
    else:
        offsets = grid * np.asarray(step, np.float32)[:, None]  # (n, size)
        # x varies along a patch row, y down a patch column: each map is one small (n, size)
        # array repeated, as a whole (x) or element by element (y), along the row
        map_x = np.tile(np.asarray(u, np.float32)[:, None] + offsets, (1, size))
        map_y = np.repeat(np.asarray(v, np.float32)[:, None] + offsets, size, axis=1)
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
