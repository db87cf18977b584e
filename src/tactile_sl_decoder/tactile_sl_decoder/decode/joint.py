"""The glyphs of several images decoded in one pass: one lattice per image, one decoding call.

Each image's lattice (:func:`~tactile_sl_decoder.decode.grid.build_grid`) is its own: the
pipeline builds it in that image's worker thread (:func:`image_lattice`; its compiled
steps release the GIL, so the two images' lattices are built side by side).  The lattices
are then laid side by side, far apart, and go through one
:class:`~tactile_sl_decoder.decode.codewords.CodewordDecoder` call: its cost is mostly per
numpy operation, so this is much cheaper than one call per image, and the result is the
same (nothing links glyphs of different images; cells are unique per image).  Cells carried
from the previous frame (:mod:`.track`) are taken instead when this frame's lattice and
labels confirm every one of them.  No rclpy.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from tactile_sl_decoder.decode.codewords import CodewordDecoder
from tactile_sl_decoder.decode.grid import Grid, GridParams, build_grid, nearest_neighbours
from tactile_sl_decoder.glyphs import Glyphs


def image_lattice(g: Glyphs, params: GridParams) -> Grid:
    """One image's lattice: its k-NN table, then the neighbourhood search.

    What the pipeline's worker threads compute per image (kept as ``g.lattice``).
    """
    # local gates: spacings that vary several fold, so no cap of 3 median spacings
    neighbours = nearest_neighbours(g.u, g.v, params.k_neighbours,
                                    0.0 if params.local_gates else g.spacing_px)
    return build_grid(g.u, g.v, params, g.spacing_px, neighbours=neighbours)


def side_by_side(grids: Sequence[Grid], offsets: Sequence[float]) -> Grid:
    """Several images' lattices as one, image ``i`` shifted by ``offsets[i]`` along u.

    Indices are renumbered to the joint order; the joint spacing is the median of all
    images' nearest-glyph distances.
    """
    nbr, pts, nearest = [], [], []
    start = 0
    for grid, shift in zip(grids, offsets):
        nbr.append(np.where(grid.nbr >= 0, grid.nbr + start, -1))
        p = np.array(grid.pts, np.float64)
        p[:, 0] += shift
        pts.append(p)
        nearest.append(grid.nearest if grid.nearest is not None
                       else np.full(len(grid.nbr), np.inf))
        start += len(grid.nbr)
    near = np.concatenate(nearest)
    near = near[np.isfinite(near)]
    spacing = float(np.median(near)) if len(near) else 0.0
    return Grid(np.concatenate(nbr), np.concatenate([g.col_vec for g in grids]),
                np.concatenate([g.row_vec for g in grids]), spacing, np.concatenate(pts),
                np.concatenate(nearest))


def decode_jointly(images: Sequence[Glyphs], decoder: CodewordDecoder, params: GridParams,
                   carried: Sequence[np.ndarray] | None = None) -> bool:
    """Give the glyphs of several images their cells in one pass (in place).

    ``carried``: per image, each glyph's cell carried from the previous frame (flat, -1
    none; :mod:`.track`).  If this frame's lattice and labels confirm every one of them, the
    glyphs take them and the window search is skipped; returns whether it was (else the
    frame was decoded in full).  An image's lattice is taken from ``lattice`` when a worker
    thread already built it.
    """
    sizes = [len(g) for g in images]
    if sum(sizes) == 0:
        return False
    offsets = []
    shift = 0.0
    for g in images:
        offsets.append(shift)
        span = float(np.max(g.u)) if len(g) else 0.0
        shift += max(span, float(g.image_width)) + 1e4       # far beyond any spacing
    label = np.concatenate([g.label for g in images])
    conf = np.concatenate([g.confidence for g in images])
    groups = np.repeat(np.arange(len(images)), sizes)
    # each image's own lattice, unless a worker thread already built it
    grid = side_by_side([g.lattice if g.lattice is not None and len(g.lattice.nbr) == len(g)
                         else image_lattice(g, params) for g in images], offsets)
    tracked = False
    if carried is not None:
        cell = np.concatenate(carried)
        ok = decoder.confirm(grid, cell, label, conf, groups)
        tracked = bool(np.all(ok | (cell == -1)))
    if tracked:
        cols = decoder.codebook.cols
        row = np.where(cell >= 0, cell // cols, -1).astype(np.int32)
        col = np.where(cell >= 0, cell % cols, -1).astype(np.int32)
    else:
        res = decoder.decode(grid, label, conf, groups)
        row, col = res.row, res.col
    start = 0
    for g, n in zip(images, sizes):
        g.row, g.col = row[start:start + n], col[start:start + n]
        if g.spacing_px <= 0:
            g.spacing_px = grid.spacing_px
        start += n
    return tracked
