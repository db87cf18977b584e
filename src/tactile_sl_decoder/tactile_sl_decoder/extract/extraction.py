"""Glyph candidates from one grey image: centres, areas, spacing and resampled patches.

The method (see ``docs/extraction.md``): a per-pixel adaptive threshold T(x, y) (local mean
minus an offset), an opening (erosion then dilation) against speckle, connected regions of
ink (the regions whose outer contours the method traces; labelling them directly gives the
same regions and their moments in one vectorised pass), rejection of regions far smaller or
larger than the typical glyph, and splitting of regions that hold two or three linked glyphs
using image moments: centroid m10/m00, m01/m00, orientation from the second-order central
moments, seeds placed along the major axis at the separation those moments imply, then a few
nearest-seed reassignments of the region's pixels. The glyph spacing is the median
nearest-neighbour distance of the detections; every patch is resampled so that it spans
``patch_span`` local spacings, whatever the magnification or stretch of the pad there.

Everything runs on whole images (OpenCV) or on flat per-pixel / per-glyph arrays (numpy):
there is no Python loop over glyphs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial import cKDTree

from tactile_sl_common.settings import SettingsTable
from tactile_sl_decoder.contract import PATCH_SIZE
from tactile_sl_decoder.extract.centroid import closing_background, patch_centroid_offset
from tactile_sl_decoder.extract.patches import sample_patches
from tactile_sl_decoder.extract.perspective import anisotropy, lattice_frames, typical_area_field
from tactile_sl_decoder.extract.spacing import estimate_spacing, median


@dataclass
class ExtractionParams:
    """Tuning of :func:`extract_symbols`; the defaults suit 12-30 px glyph spacing.

    Sizes that must follow the image scale are relative to the typical glyph (median region
    area) or to the measured spacing, so one set of defaults covers near and far pads.
    """

    block_size: int = 31
    """Side of the local-mean window of the adaptive threshold, px (odd; ~1.5-2 spacings so
    that every window holds ink and background)."""
    offset: float = 8.0
    """Grey levels below the local mean a pixel must be to count as ink (the "C" of
    cv2.adaptiveThreshold); raises the threshold above sensor noise on bare background."""
    dark_glyphs: bool = True
    """Ink darker than the pad (printed pattern seen in reflected light); False for bright."""
    open_size: int = 3
    """Side of the square erosion/dilation kernel, px (0 or 1 = no opening)."""
    min_area_px: float = 4.0
    """Regions smaller than this never count, whatever the typical glyph size."""
    min_area_ratio: float = 0.3
    """Regions below this fraction of the typical glyph area are noise."""
    split_ratio: float = 1.55
    """A region of at least this many typical areas holds two linked glyphs ..."""
    triple_ratio: float = 2.3
    """... of at least this many, three ..."""
    max_area_ratio: float = 5.0
    """... and one above this many is no glyph (shadow, smear, pad edge) and is dropped."""
    split_iterations: int = 3
    """Nearest-seed reassignments refining the centres of split regions."""
    min_split_distance: float = 0.45
    """Parts of a split region closer than this many spacings are one glyph fewer (an ink
    bridge or a swollen glyph inflated the area, not an extra glyph)."""
    core_radius: float = 0.2
    """Radius, in spacings, of the disc around a split part's centre that must be inked ..."""
    min_core_fill: float = 0.7
    """... to at least this fraction, else the part is a bridge and the region one glyph fewer
    (0 disables the check)."""
    reject_border: bool = True
    """Drop regions touching the image border: their centroid is that of a cut glyph."""
    patch_size: int = PATCH_SIZE
    """Side of the output patches, px."""
    patch_span: float = 1.0
    """Patch side in local glyph spacings (1.0 = from half-way to the left neighbour to
    half-way to the right one)."""
    default_spacing_px: float = 18.0
    """Spacing assumed when fewer than two glyphs are found."""
    refine: bool = True
    """Refine single-glyph centres to the grey-weighted centroid of their patch."""
    refine_split: int = 1
    """Grey-weighted centroid passes for the glyphs split out of linked regions, 0 = none.
    Their centres are those of a region's parts, which a dark blob of a touching object
    merged with the glyph pulls aside; the centroid of the patch around them moves them
    back (realistic noise and text objects: 3-D RMSE 0.0107 / 0.0117 -> 0.0098 / 0.0096 mm;
    docs/robustness.md).  Each pass samples those patches again."""
    split_centroid_radius: float = 0.3
    """Disc radius, in patch sides, of that centroid: smaller than the single glyphs' 0.45 so
    that a linked neighbour glyph (0.55-0.7 spacings away) stays outside; at 0.35 and above
    it pulled linked glyph pairs' centres further off than no refinement."""
    centroid_flatten: bool = True
    """Weigh those centroids from a threshold plane parallel to the patch's background (the
    plane through its border pixels) instead of its flat mean: an illumination gradient, a
    shadow's rim or a hot spot no longer pulls the centre towards the darker side
    (:func:`patch_centroid_offset`; docs/robustness.md)."""
    centroid_level: float = 0.5
    """Where that plane lies, from the patch mean (0) to the background (1)."""
    centroid_plane_misfit: float = 0.15
    """A patch whose border pixels stray from their plane by more than this fraction of its
    level (rms) keeps the flat mean: its background is no plane (an object's texture)."""
    centroid_background: bool = True
    """... unless the image's local background (grey closing over 0.75 spacings: glyphs
    removed) steps across it, at a dark object's rim: then the threshold follows that
    background (single glyphs; :func:`~tactile_sl_decoder.extract.centroid.
    patch_centroid_offset`)."""
    centroid_background_step: float = 0.5
    """The step, (max - min) / mean of the patch's background, above which it is followed."""
    rethreshold_large: bool = True
    """Look again inside regions too large to be glyphs, with a threshold from those
    regions' own pixels: a dark object touching the pad (seen through it between the glyphs)
    merges with the ink under the image-wide threshold near its rim."""
    large_offset: float = 8.0
    """Grey levels below the local background (closing) a pixel of a large region must be
    to count as ink."""
    split_linked_large: bool = True
    """Inside those regions, split the parts that are still linked (glyphs joined by the
    stripes of a striped object seen through the pad) by Otsu's threshold of each part's
    ink ratio: the printed ink is darker than anything seen through the pad."""
    perspective: bool = False
    """Follow a glyph scale and lattice shape that vary strongly across the image (a target
    tilted by 30-40 deg close to the cameras; :mod:`.perspective`): region areas are judged
    against a typical area fitted as a smooth function of the position, and patches are
    resampled through each glyph's local lattice frame (de-skewed, anisotropic scale).
    Engages only past the two thresholds below; the calibration's decoder turns it on
    (docs/calibration.md), the sensor's pipeline leaves it off."""
    perspective_scale_range: float = 1.5
    """The typical area must vary by more than this factor (5th to 95th percentile over the
    glyphs) for the area gates to follow it ..."""
    perspective_anisotropy: float = 1.12
    """... and the median lattice frame be more anisotropic than this (ratio of its
    singular values), or the scale vary as above, for the patches to follow the frames."""

    def validate(self) -> "ExtractionParams":
        """Raise ValueError naming the first setting outside :data:`EXTRACTION_SETTINGS`."""
        EXTRACTION_SETTINGS.check(self)
        return self


def _odd(value: int) -> str | None:
    return None if int(value) % 2 else "must be odd (adaptive threshold window)"


EXTRACTION_SETTINGS = SettingsTable(ExtractionParams, ranges={
    "block_size": (3, 1001), "offset": (-255.0, 255.0), "open_size": (0, 51),
    "min_area_px": (0.0, 1e6), "min_area_ratio": (0.0, 100.0), "split_ratio": (1.0, 100.0),
    "triple_ratio": (1.0, 100.0), "max_area_ratio": (1.0, 1000.0),
    "split_iterations": (0, 100), "min_split_distance": (0.0, 10.0),
    "core_radius": (0.0, 10.0), "min_core_fill": (0.0, 1.0), "patch_size": (4, 256),
    "patch_span": (0.1, 10.0), "default_spacing_px": (1.0, 10000.0),
    "large_offset": (-255.0, 255.0), "refine_split": (0, 5),
    "split_centroid_radius": (0.05, 0.5), "centroid_level": (0.0, 1.0),
    "centroid_plane_misfit": (0.0, 10.0), "centroid_background_step": (0.0, 10.0),
    "perspective_scale_range": (1.0, 100.0), "perspective_anisotropy": (1.0, 100.0),
}, read_only=("patch_size",), checks={"block_size": _odd})
"""Every field is a node parameter (``symbol_extractor``: bare, ``decoder``:
``extraction.<field>``); ``patch_size`` is the classifier's input size, set at start only."""


@dataclass
class Detections:
    """Glyph candidates of one image as flat arrays (element i = glyph i).

    Coordinates follow OpenCV: (0, 0) is the centre of the top-left pixel.
    """

    u: np.ndarray
    """Centre column, px (float32)."""
    v: np.ndarray
    """Centre row, px (float32)."""
    area: np.ndarray
    """Ink area, px^2 (float32); a split region's area is shared among its glyphs."""
    spacing_px: float
    """Median nearest-neighbour distance between centres, px (0 when unknown)."""
    patches: np.ndarray
    """(N, patch_size, patch_size) uint8 grey patches centred on each glyph."""
    local_spacing: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    """Per-glyph spacing used to scale its patch, px (float32)."""

    def __len__(self) -> int:
        return int(self.u.shape[0])

    @staticmethod
    def empty(patch_size: int = PATCH_SIZE) -> Detections:
        """No glyph (blank, saturated or featureless image)."""
        z = np.zeros(0, np.float32)
        return Detections(z, z.copy(), z.copy(), 0.0,
                          np.zeros((0, patch_size, patch_size), np.uint8), z.copy())


def threshold_ink(gray: np.ndarray, params: ExtractionParams) -> np.ndarray:
    """Binary ink mask (uint8 0/255): adaptive threshold T(x, y) = local mean - offset, opened."""
    block = max(3, int(params.block_size) | 1)
    # cv2.adaptiveThreshold(MEAN_C) is a box filter and then a per-pixel table look-up; the
    # same test as a saturating difference and a threshold (vectorised) is faster. Ink is
    # mean - grey >= floor(offset) (dark) or grey - mean > floor(offset) (bright) -- exactly
    # OpenCV's rounding of the offset -- which a saturating difference decides whenever the
    # bound is positive.
    bound = math.floor(params.offset)
    if bound >= 1 or (bound >= 0 and not params.dark_glyphs):
        mask = cv2.blur(gray, (block, block), borderType=cv2.BORDER_REPLICATE)
        if params.dark_glyphs:
            cv2.subtract(mask, gray, dst=mask)
            cv2.threshold(mask, bound - 1, 255, cv2.THRESH_BINARY, dst=mask)
        else:
            cv2.subtract(gray, mask, dst=mask)
            cv2.threshold(mask, bound, 255, cv2.THRESH_BINARY, dst=mask)
    else:
        mode = cv2.THRESH_BINARY_INV if params.dark_glyphs else cv2.THRESH_BINARY
        offset = params.offset if params.dark_glyphs else -params.offset
        mask = cv2.adaptiveThreshold(gray, 255, cv2.ADAPTIVE_THRESH_MEAN_C, mode, block, offset)
    if params.open_size > 1:
        kernel = np.ones((params.open_size, params.open_size), np.uint8)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
    return mask


def extract_symbols(gray: np.ndarray, params: ExtractionParams | None = None) -> Detections:
    """Find the glyphs of one grey image (H, W) uint8: centres, areas, spacing, patches."""
    params = params or ExtractionParams()
    gray = np.ascontiguousarray(gray)
    if gray.ndim != 2 or gray.dtype != np.uint8:
        raise ValueError(f"expected a 2-D uint8 grey image, got {gray.dtype} {gray.shape}")
    if gray.size == 0:
        return Detections.empty(params.patch_size)
    mask = threshold_ink(gray, params)
    box = _ink_box(mask)
    if box is None:
        return Detections.empty(params.patch_size)
    ox, oy, roi = box
    count, labels, stats, centroids = cv2.connectedComponentsWithStatsWithAlgorithm(
        roi, 8, cv2.CV_32S, cv2.CCL_BBDT)
    if count <= 1:
        return Detections.empty(params.patch_size)
    pixels = stats[:, cv2.CC_STAT_AREA]
    keep = pixels >= params.min_area_px
    keep[0] = False  # background
    if params.reject_border:
        h, w = gray.shape
        x0, y0 = stats[:, cv2.CC_STAT_LEFT] + ox, stats[:, cv2.CC_STAT_TOP] + oy
        keep &= (x0 > 0) & (y0 > 0) & (x0 + stats[:, cv2.CC_STAT_WIDTH] < w) & (
            y0 + stats[:, cv2.CC_STAT_HEIGHT] < h)
    if not keep.any():
        return Detections.empty(params.patch_size)
    typical = median(pixels[keep])
    ratio = pixels / typical
    if ox or oy:
        centroids += (ox, oy)
    # the typical area where each region lies (tilted views), and its largest value
    ratio, search_area, scale_varies = _perspective_ratio(centroids, pixels, keep, ratio,
                                                          typical, params)
    keep &= (ratio >= params.min_area_ratio) & (ratio <= params.max_area_ratio)
    single = np.flatnonzero(keep & (ratio < params.split_ratio))
    multi = np.flatnonzero(keep & (ratio >= params.split_ratio))
    ns = len(single)
    extra = np.zeros((0, 3))
    linked = np.zeros((0, 3))    # glyphs found in linked parts of large regions
    if params.rethreshold_large:
        large = np.flatnonzero((pixels >= params.min_area_px) & (ratio > params.max_area_ratio))
        large = large[large > 0]
        if len(large):
            extra, linked = _glyphs_in_large_regions(roi, gray, ox, oy, labels, large,
                                                     typical, params)
            ns += len(extra)
    split = np.zeros((3, 0))
    if len(multi):
        # preliminary spacing from the single glyphs: splits closer than a fraction of it
        # are not two glyphs
        pre = _median_nn(centroids[single]) if ns >= 2 else 0.0
        k = np.where(ratio[multi] >= params.triple_ratio, 3, 2)
        split = np.array(split_regions(labels, stats[multi], multi, k,
                                       params.split_iterations, params.min_split_distance * pre,
                                       params.core_radius * pre, params.min_core_fill))
        split[:2] += ((ox,), (oy,))
    # singles, glyphs inside large regions, split glyphs, glyphs of linked parts (the last
    # two refined alike below: a stripe or a linked neighbour is no part of the glyph)
    uu, vv, aa = (np.concatenate((first, extra[:, i], split[i], linked[:, i])).astype(np.float32)
                  for i, first in enumerate((centroids[single, 0], centroids[single, 1],
                                             pixels[single])))
    spacing, local = estimate_spacing(uu, vv, params.default_spacing_px,
                                      search_px=2.4 * np.sqrt(search_area))
    step: np.ndarray = local * np.float32(params.patch_span / params.patch_size)
    step, local = _perspective_steps(uu, vv, step, local, search_area, scale_varies, params)
    patches = sample_patches(gray, uu, vv, step, params.patch_size)
    if params.refine and ns:
        # binary centroids are quantised by the threshold; the grey-weighted centroid of the
        # (already resampled) patch is several times more precise under blur
        back = (closing_background(gray, uu[:ns], vv[:ns], step[:ns], params.patch_size,
                                   spacing) if params.centroid_background else None)
        du, dv = patch_centroid_offset(patches[:ns], params.dark_glyphs,
                                       flatten=params.centroid_flatten,
                                       level=params.centroid_level,
                                       tolerance=params.centroid_plane_misfit,
                                       background=back,
                                       background_step=params.centroid_background_step)
        du, dv = _patch_to_image(du, dv, step[:ns])
        uu[:ns] += du
        vv[:ns] += dv
    if params.refine and params.refine_split > 0 and len(uu) > ns:
        cut = slice(ns, len(uu))   # glyphs split out of linked regions or linked parts
        sub = patches[cut]
        for _ in range(params.refine_split):
            du, dv = patch_centroid_offset(sub, params.dark_glyphs,
                                           params.split_centroid_radius,
                                           params.centroid_flatten, params.centroid_level,
                                           params.centroid_plane_misfit)
            du, dv = _patch_to_image(du, dv, step[cut])
            uu[cut] += du
            vv[cut] += dv
            sub = sample_patches(gray, uu[cut], vv[cut], step[cut], params.patch_size)
        patches[cut] = sub                 # the classifier sees them centred
    return Detections(uu, vv, aa, spacing, patches, local)


def _patch_to_image(du: np.ndarray, dv: np.ndarray, step: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """A shift in patch pixels as a shift in image pixels (square or affine patches)."""
    if step.ndim == 1:
        return du * step, dv * step
    return ((step[:, 0, 0] * du + step[:, 0, 1] * dv).astype(np.float32),
            (step[:, 1, 0] * du + step[:, 1, 1] * dv).astype(np.float32))


def _perspective_ratio(centroids: np.ndarray, pixels: np.ndarray, keep: np.ndarray,
                       ratio: np.ndarray, typical: float, params: ExtractionParams
                       ) -> tuple[np.ndarray, float, bool]:
    """Region areas over the typical glyph area where they lie; its largest value; if used.

    The field (:func:`.perspective.typical_area_field`) is fitted to the regions that pass
    the image-wide gates; it replaces the one typical area when its 5th-95th percentile
    range over them exceeds ``perspective_scale_range``.  Otherwise, and without
    ``params.perspective``, (ratio, typical, False) as they came.  The largest value is
    taken over the fitted regions only (the quadratic is not extrapolated to stray specks
    beyond the pattern).
    """
    if not params.perspective:
        return ratio, typical, False
    at = np.flatnonzero(keep & (ratio >= params.min_area_ratio)
                        & (ratio <= params.max_area_ratio))
    field = typical_area_field(centroids[at, 0], centroids[at, 1], pixels[at])
    if field is None:
        return ratio, typical, False
    local = field(centroids[:, 0], centroids[:, 1])
    low, high = np.percentile(local[at], (5.0, 95.0))
    if high < params.perspective_scale_range * low:
        return ratio, typical, False
    return pixels / local, float(local[at].max()), True


def _perspective_steps(u: np.ndarray, v: np.ndarray, step: np.ndarray, local: np.ndarray,
                       largest_area: float, scale_varies: bool, params: ExtractionParams
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Patch steps through the local lattice frames, (N, 2, 2), and the local spacings.

    The frames (:func:`.perspective.lattice_frames`) replace the square patches when the
    scale varies (``scale_varies``) or the median frame is more anisotropic than
    ``perspective_anisotropy``; otherwise, and without ``params.perspective``, (step,
    local) as they came.  The local spacing becomes sqrt(det frame), the side of the square
    of the same area.
    """
    if not params.perspective or len(u) < 5:
        return step, local
    frames = lattice_frames(u, v, 2.4 * math.sqrt(largest_area))
    if not scale_varies and median(anisotropy(frames)) < params.perspective_anisotropy:
        return step, local
    return (frames * np.float32(params.patch_span / params.patch_size),
            np.sqrt(np.abs(np.linalg.det(frames))).astype(np.float32))


def _glyphs_in_large_regions(roi: np.ndarray, gray: np.ndarray, ox: int, oy: int,
                             labels: np.ndarray, large: np.ndarray, typical: float,
                             params: ExtractionParams) -> tuple[np.ndarray, np.ndarray]:
    """Single glyphs inside regions too large to be glyphs: two (n, 3) u, v, area arrays.

    Inside such a region (a dark object seen through the pad, a shadow's rim) the ink is
    still darker than its surroundings, but the image-wide threshold counted the background
    as ink too.  Morphological black-hat (closing minus image) with a square a little
    larger than a glyph keeps only dark features smaller than a glyph, whatever the
    background level around them (object, its rim, paper); it is thresholded at
    ``large_offset`` grey levels inside the large regions.  Parts of a single glyph's size
    are the first array.

    Parts still too large after that (glyphs linked by the stripes of a striped object, a
    stripe being thinner than the square) are split by ``split_linked_large``
    (:func:`_glyphs_in_linked_parts`): the second array.
    """
    lut = np.zeros(int(labels.max()) + 1, np.uint8)
    lut[large] = 1
    region = lut[labels]
    h, w = region.shape
    g = gray[oy:oy + h, ox:ox + w]
    if g.shape != region.shape:
        g = cv2.copyMakeBorder(g, 0, h - g.shape[0], 0, w - g.shape[1], cv2.BORDER_REPLICATE)
    side = int(np.clip(2.0 * math.sqrt(typical), 5, 41)) | 1
    kernel = np.ones((side, side), np.uint8)
    op = cv2.MORPH_BLACKHAT if params.dark_glyphs else cv2.MORPH_TOPHAT
    hat = cv2.morphologyEx(g, op, kernel, borderType=cv2.BORDER_REPLICATE)
    ink = ((region > 0) & (hat >= params.large_offset)).astype(np.uint8) * 255
    if params.open_size > 1:
        ink = cv2.morphologyEx(ink, cv2.MORPH_OPEN,
                               np.ones((params.open_size, params.open_size), np.uint8))
    none = np.zeros((0, 3))
    count, lab, stats, cent = cv2.connectedComponentsWithStatsWithAlgorithm(
        ink, 8, cv2.CV_32S, cv2.CCL_BBDT)
    if count <= 1:
        return none, none
    area = stats[1:, cv2.CC_STAT_AREA].astype(np.float64)
    ratio = area / typical
    ok = (ratio >= max(params.min_area_ratio, 0.5)) & (ratio < params.split_ratio)
    ok &= area >= params.min_area_px
    c = cent[1:][ok]
    single = np.column_stack([c[:, 0] + ox, c[:, 1] + oy, area[ok]])
    linked = np.flatnonzero(ratio >= params.split_ratio) + 1
    if not params.split_linked_large or not len(linked):
        return single, none
    # only the box around those parts (even corners, as in _ink_box: BBDT's 2x2 blocks)
    x0 = int(stats[linked, cv2.CC_STAT_LEFT].min()) & ~1
    y0 = int(stats[linked, cv2.CC_STAT_TOP].min()) & ~1
    x1 = min(w, (int((stats[linked, cv2.CC_STAT_LEFT] + stats[linked, cv2.CC_STAT_WIDTH]).max())
                 + 1) & ~1)
    y1 = min(h, (int((stats[linked, cv2.CC_STAT_TOP] + stats[linked, cv2.CC_STAT_HEIGHT]).max())
                 + 1) & ~1)
    box = (slice(y0, y1), slice(x0, x1))
    found = _glyphs_in_linked_parts(g[box], hat[box], lab[box], count, linked, typical,
                                    params)
    found[:, 0] += ox + x0
    found[:, 1] += oy + y0
    return single, found


def _glyphs_in_linked_parts(g: np.ndarray, hat: np.ndarray, lab: np.ndarray, count: int,
                            linked: np.ndarray, typical: float,
                            params: ExtractionParams) -> np.ndarray:
    """Glyphs inside black-hat parts that are still linked: (n, 3) u, v, area.

    ``g``, ``hat`` and ``lab`` are the grey image, its black-hat (top-hat for bright ink)
    and the labels of the black-hat parts over the same window (coordinates returned in
    it); ``count`` labels in all, ``linked`` those of the parts to split.

    A striped object seen through the pad links glyphs and stripe segments into long
    regions that survive the black-hat (a stripe is thinner than its square).  The printed
    ink is darker than anything seen through the pad, so each such part is split in two by
    Otsu's threshold (N. Otsu, "A threshold selection method from gray-level histograms",
    IEEE Trans. SMC 9(1), 1979: the level maximising the between-class variance of the
    part's histogram).  The histogram is of the ratio grey / closing (the image over its
    local bright level: the local reflectance under a multiplicative illumination model),
    not of the black-hat difference: a stripe's black-hat grows with the bright level around
    it (paper beyond the object's rim), its ratio does not (one part's black-hat histogram
    had its threshold inside the stripes' mode).  All parts' histograms and thresholds at
    once (one bincount, cumulative sums); the darker class, opened, gives the parts of one
    glyph's size (at least ``min_area_ratio``: the dark class is a glyph's core, not all of
    its blurred edge).

    Their centres lean towards a stripe the glyph overlaps: on that side the threshold cuts
    the glyph's blurred edge nearer the stripe (its contrast with the stripe is low), on the
    other side nearer the ink.  0.4-0.55 px median on the sweep's realistic stripes,
    up to 1.3 px on the synthetic test image; coverage, not accuracy, is what they add.
    """
    n = len(linked)
    lut = np.zeros(count, np.int32)     # label of lab -> 1 + index in linked, 0 = other
    lut[linked] = np.arange(1, n + 1)
    part = lut[lab].ravel()
    idx = np.flatnonzero(part)
    part = part[idx] - 1
    grey = g.ravel()[idx].astype(np.float32)
    # the closing (the opening under a top-hat, bright ink): the local background level
    backdrop = grey + hat.ravel()[idx] if params.dark_glyphs else grey - hat.ravel()[idx]
    # 0..255, larger = more ink-like (darker than the local bright level for dark glyphs)
    level = grey / np.maximum(backdrop, 1.0)
    if params.dark_glyphs:
        level = 1.0 - level
    else:
        level = 1.0 - 1.0 / np.maximum(level, 1.0)
    q = np.clip(np.rint(255.0 * level), 0, 255).astype(np.int64)
    hist = np.bincount(part * 256 + q, minlength=n * 256).reshape(n, 256).astype(np.float64)
    t = _otsu_levels(hist)
    dark_class = np.zeros(g.size, np.uint8)
    dark_class[idx[q > t[part]]] = 255
    core: np.ndarray = dark_class.reshape(g.shape)
    if params.open_size > 1:
        core = cv2.morphologyEx(core, cv2.MORPH_OPEN,
                                np.ones((params.open_size, params.open_size), np.uint8))
    found, _lab, stats, cent = cv2.connectedComponentsWithStatsWithAlgorithm(
        core, 8, cv2.CV_32S, cv2.CCL_BBDT)
    if found <= 1:
        return np.zeros((0, 3))
    area = stats[1:, cv2.CC_STAT_AREA].astype(np.float64)
    ratio = area / typical
    ok = (ratio >= params.min_area_ratio) & (ratio < params.split_ratio)
    ok &= area >= params.min_area_px
    c = cent[1:][ok]
    return np.column_stack([c[:, 0], c[:, 1], area[ok]])


def _otsu_levels(hist: np.ndarray) -> np.ndarray:
    """Otsu's threshold of each row of (n, L) histograms: the last level of the dark class.

    Between-class variance (N mu(t) - mu_T w(t))^2 / (w(t) (N - w(t))) up to a constant
    factor, with w, mu the cumulative counts and first moments (Otsu 1979, eq. 18).
    """
    levels = np.arange(hist.shape[1], dtype=np.float64)
    w = np.cumsum(hist, axis=1)
    mu = np.cumsum(hist * levels, axis=1)
    total, mu_t = w[:, -1:], mu[:, -1:]
    with np.errstate(invalid="ignore", divide="ignore"):
        between = (mu_t * w - mu * total) ** 2 / (w * (total - w))
    between[~np.isfinite(between)] = -1.0
    return np.argmax(between, axis=1)


def _ink_box(mask: np.ndarray) -> tuple[int, int, np.ndarray] | None:
    """Offset (x, y) and view of the part of ``mask`` to label: the bounding box of its ink.

    Labelling only the box (the pad often fills part of the frame) gives the same regions
    from fewer pixels. The box starts at even coordinates and has even sides: BBDT labels
    2x2 blocks, so the regions come out in the same order as over the whole image, and
    OpenCV's BBDT with statistics is ~1.5x slower on an odd width or height. None when
    there is no ink.
    """
    ox, oy, bw, bh = cv2.boundingRect(mask)
    if bw == 0 or bh == 0:
        return None
    x0, y0 = ox & ~1, oy & ~1
    x1, y1 = (ox + bw + 1) & ~1, (oy + bh + 1) & ~1
    h, w = mask.shape
    roi = mask[y0:y1, x0:x1]
    if x1 > w or y1 > h:  # an odd image side: pad with background
        roi = cv2.copyMakeBorder(roi, 0, y1 - min(y1, h), 0, x1 - min(x1, w),
                                 cv2.BORDER_CONSTANT, value=0)
    return x0, y0, roi


def _median_nn(points: np.ndarray, sample: int = 64) -> float:
    """Median nearest-neighbour distance of (a fixed subsample of) points."""
    tree = cKDTree(points)
    probe = points[:: max(1, len(points) // sample)]
    dist, _ = tree.query(probe, k=2)
    return median(dist[:, 1])


def split_regions(labels: np.ndarray, stats: np.ndarray, ids: np.ndarray, k: np.ndarray,
                  iterations: int = 3, min_separation_px: float = 0.0,
                  core_radius_px: float = 0.0, min_core_fill: float = 0.7
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres of the k glyphs in each linked region, from its moments (all regions at once).

    Seeds lie on the major axis (orientation from the second-order central moments) through
    the centroid (m10/m00, m01/m00). For k equal blobs spaced d apart on a line, the variance
    along the axis exceeds the across-axis variance by d^2/4 (k = 2) or 2 d^2/3 (k = 3),
    which gives d; nearest-seed reassignment of the pixels then corrects for unequal glyph
    shapes and bent chains. A region whose parts end up closer than ``min_separation_px``
    (a pair plus a long ink bridge counted as three by its area, a swollen single glyph
    counted as two) is split into one glyph fewer. Returns centres and part pixel counts.
    """
    n = len(ids)
    x0 = stats[:, cv2.CC_STAT_LEFT].astype(np.int64)
    y0 = stats[:, cv2.CC_STAT_TOP].astype(np.int64)
    bw = stats[:, cv2.CC_STAT_WIDTH].astype(np.int64)
    bh = stats[:, cv2.CC_STAT_HEIGHT].astype(np.int64)
    sizes = bw * bh
    r = np.repeat(np.arange(n), sizes)  # every pixel of every bounding box, region-major
    local = np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    px = x0[r] + local % bw[r]
    py = y0[r] + local // bw[r]
    own = labels[py, px] == ids[r]
    r, px, py = r[own], px[own].astype(np.float64), py[own].astype(np.float64)
    m00 = np.bincount(r, minlength=n).astype(np.float64)
    cu = np.bincount(r, px, minlength=n) / m00
    cv = np.bincount(r, py, minlength=n) / m00
    dx = px - cu[r]
    dy = py - cv[r]
    mu20 = np.bincount(r, dx * dx, minlength=n) / m00
    mu02 = np.bincount(r, dy * dy, minlength=n) / m00
    mu11 = np.bincount(r, dx * dy, minlength=n) / m00
    theta = 0.5 * np.arctan2(2.0 * mu11, mu20 - mu02)
    spread = 2.0 * np.sqrt(((mu20 - mu02) / 2.0) ** 2 + mu11 ** 2)  # lambda_max - lambda_min
    k = np.asarray(k, np.int64).copy()
    slots = np.arange(3, dtype=np.float64)
    for _ in range(3):  # at most two reductions of k (3 -> 2 -> 1)
        step = np.where(k == 3, np.sqrt(1.5 * spread), 2.0 * np.sqrt(spread))
        # seed j of region i at offset (j - (k-1)/2) * step on the axis; unused slots = inf
        offset = (slots[None, :] - (k[:, None] - 1) / 2.0) * step[:, None]
        valid = slots[None, :] < k[:, None]
        seed_u = np.where(valid, cu[:, None] + offset * np.cos(theta)[:, None], np.inf)
        seed_v = np.where(valid, cv[:, None] + offset * np.sin(theta)[:, None], np.inf)
        slot = r * 3
        for _ in range(max(1, iterations)):  # a fixed few passes over all regions' pixels
            d2 = (px[:, None] - seed_u[r]) ** 2 + (py[:, None] - seed_v[r]) ** 2
            slot = r * 3 + np.argmin(d2, axis=1)
            sums = np.bincount(slot, minlength=3 * n).reshape(n, 3).astype(np.float64)
            su = np.bincount(slot, px, minlength=3 * n).reshape(n, 3)
            sv = np.bincount(slot, py, minlength=3 * n).reshape(n, 3)
            ok = valid & (sums > 0)
            with np.errstate(invalid="ignore", divide="ignore"):
                seed_u = np.where(ok, su / sums, seed_u)
                seed_v = np.where(ok, sv / sums, seed_v)
        # closest two parts of each region (inf - inf pairs of unused slots -> nan -> ignored)
        with np.errstate(invalid="ignore"):
            gaps = np.stack([np.hypot(seed_u[:, a] - seed_u[:, b], seed_v[:, a] - seed_v[:, b])
                             for a, b in ((0, 1), (0, 2), (1, 2))], axis=1)
        closest = np.nanmin(np.where(np.isfinite(gaps), gaps, np.nan), axis=1,
                            initial=np.inf) if n else np.zeros(0)
        fewer = (k > 1) & (closest < min_separation_px)
        if core_radius_px > 0:
            # a glyph has solid ink around its centre; a part centred on a thin bridge does not
            d2 = (px[:, None] - seed_u[r]) ** 2 + (py[:, None] - seed_v[r]) ** 2
            near = d2 < core_radius_px ** 2
            hits = np.bincount((r[:, None] * 3 + slots[None, :].astype(np.int64))[near],
                               minlength=3 * n).reshape(n, 3)
            fill = hits / (np.pi * core_radius_px ** 2)
            hollow = (valid & (fill < min_core_fill)).any(axis=1)
            fewer |= (k > 1) & hollow
        if not fewer.any():
            break
        k[fewer] -= 1
    counts = np.bincount(slot, minlength=3 * n).reshape(n, 3).astype(np.float64)
    ok = (slots[None, :] < k[:, None]) & (counts > 0)
    return seed_u[ok], seed_v[ok], counts[ok]
