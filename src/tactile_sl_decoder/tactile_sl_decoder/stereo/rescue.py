"""Glyphs one camera did not detect at all, measured where the other camera's cell puts them.

:mod:`.transfer` gives a cell to a glyph the target camera *found* but could not decode.
Where the target camera sees the pad worst (its own vignetting corner under a darker
exposure, the rim of a dark object) the adaptive threshold may not find the glyph at all:
its ink is a few grey levels below the background, and the region left after the threshold
and the opening is too small to count. The glyph is still there, and the other camera
decoded its cell. Such a cell ``C`` is looked for in the target *image* at

    uv_target(C) ~= uv_source(C) + median_N (uv_target(N) - uv_source(N))

(raw pixels, over the lattice neighbours ``N`` of ``C`` decoded in both images; as in
:mod:`.transfer`, the offset between the two views varies little from one glyph to the
next). The glyph is measured there like every other single glyph: the grey-weighted
centroid of its patch (:func:`~tactile_sl_decoder.extract.centroid.patch_centroid_offset`
with the extraction's threshold plane), re-sampled around the new centre and repeated
(``passes``), since the prediction may miss by a fraction of a pixel. It then counts only if

* no glyph of the target image lies within ``clearance`` spacings of the prediction (a
  glyph there is :mod:`.transfer`'s business, or a blob this must not duplicate);
* at least ``min_neighbours`` neighbours of ``C`` are decoded in both images and their
  offsets agree (spread below ``radius`` spacings);
* the centre moved less than ``radius`` spacings from the prediction (a glyph sits there,
  not a neighbour's edge or a speck the centroid ran to);
* the patch holds ink: its central disc is darker than its border by at least
  ``min_contrast`` times the median of the same measure over the glyphs the target image
  did detect (a worn-off or missing glyph has none);
* the classifier does not read another symbol there (unknown or the cell's symbol).

The measurement then meets the same stereo and surface-outlier gates as any other pair
(:func:`~tactile_sl_decoder.stereo.pair.pair_points`). Like the detection it
stands in for, it is a measurement of the image: a guided search, the correspondence
step of model-based tracking (G. Klein and D. Murray, "Parallel Tracking and Mapping for
Small AR Workspaces", ISMAR 2007, sec. 5.2: patches searched for at their predicted
positions), here predicted from the other camera instead of the last frame. It needs the
grey images, so it runs on the images path only (not on chained symbol inputs).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from scipy.spatial import cKDTree

from tactile_sl_common.settings import SettingsTable
from tactile_sl_decoder.contract import LABEL_UNKNOWN
from tactile_sl_decoder.extract.centroid import patch_centroid_offset
from tactile_sl_decoder.extract.patches import sample_patches
from tactile_sl_decoder.glyphs import Glyphs
from tactile_sl_decoder.stereo.transfer import cell_table, predict_missing


@dataclass
class RescueParams:
    """Settings of :func:`rescue_pair` (the decoder node's ``rescue.*`` parameters)."""

    enabled: bool = True
    """A cell the other image decoded where this image found no glyph is measured in this
    image where the neighbouring cells put it."""
    radius: float = 0.2
    """Largest move of the measured centre from the prediction, and largest spread of the
    neighbours' offsets, glyph spacings."""
    clearance: float = 0.6
    """No detected glyph of the target image may lie this close to the prediction, glyph
    spacings."""
    min_neighbours: int = 2
    """Neighbouring cells decoded in both images needed to predict a cell's place."""
    min_contrast: float = 0.5
    """Ink contrast needed, as a fraction of the median contrast of the detected glyphs."""
    centroid_passes: int = 3
    """Centroid passes (each re-samples the patch around the last centre)."""
    grow_passes: int = 8
    """Growth passes (each can measure cells next to those the last one measured; 0 = off)."""

    def validate(self) -> "RescueParams":
        """Raise ValueError naming the first setting outside :data:`RESCUE_SETTINGS`."""
        RESCUE_SETTINGS.check(self, "rescue.")
        return self


RESCUE_SETTINGS = SettingsTable(RescueParams, ranges={
    "radius": (0.01, 0.45), "clearance": (0.1, 1.0), "min_neighbours": (1, 8),
    "min_contrast": (0.0, 2.0), "centroid_passes": (1, 10), "grow_passes": (0, 64)})
"""The decoder node's live ``rescue.<field>`` parameters."""


@dataclass
class Rescued:
    """Glyphs measured in one image at cells the other image decoded."""

    uv: np.ndarray        # (M, 2) float64 raw pixels
    cell: np.ndarray      # (M,) int64 row * cols + col
    label: np.ndarray     # (M,) uint8 the classifier's reading there (unknown or the symbol)

    @staticmethod
    def none() -> "Rescued":
        return Rescued(np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0, np.uint8))


def rescue_pair(left: Glyphs, right: Glyphs, images: tuple[np.ndarray, np.ndarray],
                symbols: np.ndarray, extraction: Any,
                classify: Callable[[np.ndarray], tuple[np.ndarray, Any]],
                params: RescueParams | None = None) -> tuple[Rescued, Rescued]:
    """Glyphs measured in the left and in the right grey image at the other's cells.

    ``extraction``: the ExtractionParams the glyphs were found with (patch size and span,
    centroid settings); ``classify``: patches -> (labels, confidences).
    """
    p = params or RescueParams()
    if not p.enabled or len(left) == 0 or len(right) == 0:
        return Rescued.none(), Rescued.none()
    tl, tr = cell_table(left, symbols.shape), cell_table(right, symbols.shape)
    uvl = np.column_stack([left.u, left.v]).astype(np.float64)
    uvr = np.column_stack([right.u, right.v]).astype(np.float64)
    return (_one_way(uvr, tr, left, uvl, tl, images[0], symbols, extraction, classify, p),
            _one_way(uvl, tl, right, uvr, tr, images[1], symbols, extraction, classify, p))


def _one_way(uv_s: np.ndarray, ts: np.ndarray, dst: Glyphs, uv_d: np.ndarray, td: np.ndarray,
             dst_gray: np.ndarray, symbols: np.ndarray, extraction: Any,
             classify: Callable[[np.ndarray], tuple[np.ndarray, Any]],
             p: RescueParams) -> Rescued:
    """Cells the source image decoded that no glyph of ``dst`` holds, measured in its image.

    ``uv_s`` / ``uv_d``: glyph centres, ``ts`` / ``td``: padded cell tables of the source
    and ``dst`` images.

    Grown pass by pass: a cell measured in one pass is a neighbour in the next, so a region
    the target camera found nothing in is filled from its rim inwards.
    """
    if len(dst) < 2 or dst.spacing_px <= 0:
        return Rescued.none()
    spacing = float(dst.spacing_px)
    detected = len(uv_d)
    table = td
    tree: cKDTree | None = None
    typical: float | None = None
    found = Rescued.none()
    for _ in range(int(p.grow_passes)):
        missing, predicted = _predict(uv_s, ts, uv_d, table, dst_gray.shape, spacing, p)
        if len(missing) == 0:
            break
        if tree is None:
            tree = cKDTree(uv_d[:detected])
        dist, _ = tree.query(predicted)
        keep = dist >= p.clearance * spacing
        missing, predicted = missing[keep], predicted[keep]
        if len(missing) == 0:
            break
        if typical is None:
            typical = _typical_contrast(dst, dst_gray, extraction, spacing)
        uv, label, ok = _measure(dst_gray, predicted, symbols[missing[:, 0], missing[:, 1]],
                                 spacing, typical, extraction, classify, p)
        if not ok.any():
            break
        rows, cols = missing[ok, 0], missing[ok, 1]
        if table is td:
            table = td.copy()
        table[rows + 1, cols + 1] = len(uv_d) + np.arange(len(rows))
        uv_d = np.concatenate([uv_d, uv[ok]])
        found = Rescued(np.concatenate([found.uv, uv[ok]]),
                        np.concatenate([found.cell,
                                        rows.astype(np.int64) * symbols.shape[1] + cols]),
                        np.concatenate([found.label, label[ok]]))
    return found


def _predict(uv_s: np.ndarray, ts: np.ndarray, uv_d: np.ndarray, td: np.ndarray,
             image_shape: tuple[int, ...], spacing: float, p: RescueParams
             ) -> tuple[np.ndarray, np.ndarray]:
    """Missing cells ((M, 2) row, col) with agreeing neighbours, and their places.

    Only places far enough inside the image for a whole glyph are kept.
    """
    missing, predicted, spread = predict_missing(uv_s, ts, uv_d, td, p.min_neighbours)
    if len(missing) == 0:
        return missing, predicted
    h, w = image_shape[:2]
    margin = 0.6 * spacing     # a glyph closer to the border is cut (extraction drops it)
    keep = ((spread <= p.radius * spacing) & (predicted >= margin).all(axis=1)
            & (predicted <= (w - 1 - margin, h - 1 - margin)).all(axis=1))
    return missing[keep], predicted[keep]


def _typical_contrast(dst: Glyphs, gray: np.ndarray, extraction: Any, spacing: float) -> float:
    """Median :func:`ink_contrast` of the glyphs the image's extraction found."""
    size = int(extraction.patch_size)
    patches = dst.patches
    if patches is None or len(patches) != len(dst) or patches.shape[1] != size:
        patches = sample_patches(gray, dst.u, dst.v,
                                 np.full(len(dst), spacing * extraction.patch_span / size,
                                         np.float32), size)
    return float(np.median(ink_contrast(patches, extraction.dark_glyphs)))


def _measure(gray: np.ndarray, predicted: np.ndarray, symbol: np.ndarray, spacing: float,
             typical: float, extraction: Any,
             classify: Callable[[np.ndarray], tuple[np.ndarray, Any]], p: RescueParams
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (M, 2), readings and acceptance of glyphs looked for at ``predicted``."""
    size = int(extraction.patch_size)
    step = np.full(len(predicted), spacing * extraction.patch_span / size, np.float32)
    u = predicted[:, 0].astype(np.float32)
    v = predicted[:, 1].astype(np.float32)
    for _ in range(int(p.centroid_passes)):
        patches = sample_patches(gray, u, v, step, size)
        du, dv = patch_centroid_offset(patches, extraction.dark_glyphs,
                                       flatten=extraction.centroid_flatten,
                                       level=extraction.centroid_level,
                                       tolerance=extraction.centroid_plane_misfit)
        u += du * step
        v += dv * step
    patches = sample_patches(gray, u, v, step, size)
    moved = np.hypot(u - predicted[:, 0], v - predicted[:, 1])
    ok = (moved <= p.radius * spacing) & (
        ink_contrast(patches, extraction.dark_glyphs) >= p.min_contrast * typical)
    label = np.full(len(predicted), LABEL_UNKNOWN, np.uint8)
    if ok.any():
        label[ok] = np.asarray(classify(patches[ok])[0], np.uint8)
        ok &= (label == LABEL_UNKNOWN) | (label == symbol)
    return np.column_stack([u, v]).astype(np.float64), label, ok


def ink_contrast(patches: np.ndarray, dark: bool = True) -> np.ndarray:
    """Relative darkening of each patch's centre against its border, 0 = none.

    (border mean - centre mean) / border mean, the centre a disc of a quarter patch side
    (inside every glyph), the border the outermost ring of pixels (the gaps between glyphs);
    sign flipped for bright glyphs.
    """
    n, size = patches.shape[0], patches.shape[1]
    if n == 0:
        return np.zeros(0)
    centre, ring = _masks(size)
    flat = patches.reshape(n, size * size).astype(np.float32)
    inner = flat[:, centre].mean(axis=1)
    outer = flat[:, ring].mean(axis=1)
    diff = (outer - inner) if dark else (inner - outer)
    return diff / np.maximum(outer, 1.0)


def _masks(size: int) -> tuple[np.ndarray, np.ndarray]:
    g = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    gx, gy = np.meshgrid(g, g)
    centre = np.flatnonzero((gx ** 2 + gy ** 2).ravel() <= (0.25 * size) ** 2)
    ring = np.flatnonzero((np.maximum(np.abs(gx), np.abs(gy)) > (size - 1) / 2.0 - 1.0).ravel())
    return centre, ring
