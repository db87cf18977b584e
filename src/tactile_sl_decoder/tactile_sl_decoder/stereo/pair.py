"""A stereo pair of decoded images to contract points: the stereo stage's sequence (no rclpy).

1. **Transfer** (:mod:`.transfer`): a glyph one image could not decode takes the cell the
   other image decoded where the pair's geometry and the neighbouring cells put it.
2. **Rescue** (:mod:`.rescue`, images path only): a cell one image decoded where the other
   holds no glyph is measured in that image where its neighbours put it (and classified).
3. **Artwork fit** (:mod:`.artwork_fit`, images path only, off by default): every glyph
   with a cell is re-centred by fitting the printed artwork around it to the image.
4. **Match and triangulate** (:mod:`.stereo`): cells decoded in both images, through the
   epipolar and depth gates.
5. **Outliers** (:mod:`.outliers`): points off the smooth surface their lattice neighbours
   define are dropped.

:class:`~tactile_sl_decoder.pipeline.StereoPipeline` calls :func:`pair_points` after
decoding both images; docs/robustness.md describes steps 1, 2, 3 and 5.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from tactile_sl_common.clouds import pack_points
from tactile_sl_decoder.extract.extraction import ExtractionParams
from tactile_sl_decoder.glyphs import Glyphs
from tactile_sl_decoder.stereo.artwork_fit import ArtworkFitParams, ArtworkModel, fit_centres
from tactile_sl_decoder.stereo.outliers import OutlierParams, surface_outliers
from tactile_sl_decoder.stereo.rescue import Rescued, RescueParams, rescue_pair
from tactile_sl_decoder.stereo.stereo import StereoParams, StereoRig, match_and_triangulate
from tactile_sl_decoder.stereo.transfer import TransferParams, needs_transfer, transfer_cells


@dataclass
class PairSettings:
    """The settings of the four steps (the pipeline's own objects: live changes apply)."""

    transfer: TransferParams
    rescue: RescueParams
    stereo: StereoParams
    outliers: OutlierParams
    extraction: ExtractionParams | None = None   # for rescue; None = the defaults
    artwork_fit: ArtworkFitParams | None = None  # None = off
    artwork: ArtworkModel | None = None          # the pattern's artwork, for the fit


@dataclass
class PairPoints:
    """What a stereo pair gave."""

    points: np.ndarray             # structured POINT_DTYPE array (x, y, z, row, col)
    rejected: int                  # cell pairs dropped by the gates and the outlier test
    assisted: tuple[int, int]      # per image, the cells that came from the other camera


def pair_points(left: Glyphs, right: Glyphs, rig: StereoRig, symbols: np.ndarray,
                settings: PairSettings,
                classify: Callable[[np.ndarray], tuple[np.ndarray, Any]],
                images: tuple[np.ndarray, np.ndarray] | None = None,
                both: Callable[[Callable[[Any], Any], Any, Any], tuple[Any, Any]] | None = None
                ) -> PairPoints:
    """Contract points of two decoded images, and per image the cells from the other camera.

    ``symbols`` is the pattern array (rows, cols); ``classify`` the classifier (patches ->
    labels, confidences), used by the rescue.  The images' ``row`` / ``col``
    are new arrays when cells are transferred (the decoder's own cells, carried to the next
    frame, stay as decoded); with the grey ``images`` glyphs the other camera did not
    detect are measured (the glyph arrays stay as extracted).
    """
    rows, ncols = symbols.shape
    assisted = (0, 0)
    uv_l = np.column_stack([left.u, left.v]).astype(np.float64)
    uv_r = np.column_stack([right.u, right.v]).astype(np.float64)
    rect_l, rect_r = left.rectified, right.rectified
    if rect_l is None or rect_r is None or len(rect_l) != len(uv_l) or len(rect_r) != len(
            uv_r):
        rect_l = rect_r = None                       # rectify the matched ones only
    if settings.transfer.enabled and len(uv_l) and len(uv_r) and needs_transfer(left, right):
        if rect_l is None or rect_r is None:
            rect_l = StereoRig.rectify(rig.left, uv_l)
            rect_r = StereoRig.rectify(rig.right, uv_r)
        before = [int(np.count_nonzero(g.row >= 0)) for g in (left, right)]
        for g in (left, right):
            g.row, g.col = g.row.copy(), g.col.copy()
        if transfer_cells(left, right, rect_l, rect_r, symbols, settings.transfer):
            assisted = (int(np.count_nonzero(left.row >= 0)) - before[0],
                        int(np.count_nonzero(right.row >= 0)) - before[1])
    cl = np.where(left.row >= 0, left.row.astype(np.int64) * ncols + left.col, -1)
    cr = np.where(right.row >= 0, right.row.astype(np.int64) * ncols + right.col, -1)
    if images is not None and settings.rescue.enabled and len(uv_l) and len(uv_r):
        extraction = settings.extraction or ExtractionParams()
        found = rescue_pair(left, right, images, symbols, extraction, classify,
                            settings.rescue)
        if len(found[0].cell) or len(found[1].cell):
            uv_l, cl, rect_l = _with_rescued(uv_l, cl, rect_l, found[0], rig.left)
            uv_r, cr, rect_r = _with_rescued(uv_r, cr, rect_r, found[1], rig.right)
            assisted = (assisted[0] + len(found[0].cell), assisted[1] + len(found[1].cell))
    fit = settings.artwork_fit
    if images is not None and fit is not None and fit.enabled and settings.artwork is not None:
        artwork = settings.artwork

        def fitted(job: tuple[Any, ...]) -> tuple[np.ndarray, np.ndarray | None]:
            gray, uv, cell, rect, cam = job
            return _fitted(gray, uv, cell, rect, cam, ncols, artwork, fit)

        (uv_l, rect_l), (uv_r, rect_r) = (both or _one_then_other)(
            fitted, (images[0], uv_l, cl, rect_l, rig.left),
            (images[1], uv_r, cr, rect_r, rig.right))
    m = match_and_triangulate(rig, uv_l, cl, uv_r, cr, ncols, settings.stereo, rect_l, rect_r)
    # Points off the smooth surface their lattice neighbours define are dropped: a glyph
    # centre pulled aside in one image (shadow edge, dust, texture) or a wrong cell.
    off = surface_outliers(m.xyz, m.row, m.col, (rows, ncols), settings.outliers)
    if off.any():
        keep = ~off
        return PairPoints(pack_points(m.xyz[keep], m.row[keep], m.col[keep]),
                          m.rejected + int(off.sum()), assisted)
    return PairPoints(pack_points(m.xyz, m.row, m.col), m.rejected, assisted)


def _one_then_other(fn: Callable[[Any], Any], a: Any, b: Any) -> tuple[Any, Any]:
    return fn(a), fn(b)


def _fitted(gray: np.ndarray, uv: np.ndarray, cell: np.ndarray, rect: np.ndarray | None,
            cam: Any, ncols: int, artwork: ArtworkModel, params: ArtworkFitParams
            ) -> tuple[np.ndarray, np.ndarray | None]:
    """One image's centres with its glyphs at cells fitted with the artwork (step 3).

    A cell held by two glyphs is left alone (the lattice does not say which is which).
    Returns new arrays (the glyph arrays stay as extracted) and the rectified centres with
    the moved ones rectified again.
    """
    if len(uv) == 0:
        return uv, rect
    _, first, counts = np.unique(cell, return_index=True, return_counts=True)
    single = first[(counts == 1) & (cell[first] >= 0)]
    if len(single) == 0:
        return uv, rect
    centres, moved = fit_centres(gray, uv[single], cell[single] // ncols, cell[single] % ncols,
                                 artwork, params)
    if not moved.any():
        return uv, rect
    index = single[moved]
    uv = uv.copy()
    uv[index] = centres[moved]
    if rect is not None:
        rect = rect.copy()
        rect[index] = StereoRig.rectify(cam, uv[index])
    return uv, rect


def _with_rescued(uv: np.ndarray, cell: np.ndarray, rect: np.ndarray | None, found: Rescued,
                  cam: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """One image's centres, cells and rectified centres with its rescued glyphs appended."""
    if len(found.cell) == 0:
        return uv, cell, rect
    if rect is not None:
        rect = np.concatenate([rect, StereoRig.rectify(cam, found.uv)])
    return np.concatenate([uv, found.uv]), np.concatenate([cell, found.cell]), rect
