"""The glyphs of several images decoded in one pass: one lattice search, one decoding call.

The images' glyphs are laid side by side, far apart, and go through one lattice search
(:func:`~tactile_sl_decoder.decode.grid.build_grid`) and one
:class:`~tactile_sl_decoder.decode.codewords.CodewordDecoder` call: the cost of these is
mostly per numpy operation, so this is much cheaper than one call per image, and the result
is the same (nothing links glyphs of different images; cells are unique per image).  Cells
carried from the previous frame (:mod:`.track`) are taken instead when this frame's lattice
and labels confirm every one of them.  No rclpy.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from tactile_sl_decoder.decode.codewords import CodewordDecoder
from tactile_sl_decoder.decode.grid import GridParams, build_grid, nearest_neighbours
from tactile_sl_decoder.glyphs import Glyphs


def glyph_neighbours(g: Glyphs, params: GridParams) -> tuple[np.ndarray, np.ndarray]:
    """k-NN table of one image's glyphs (the lattice search's first step)."""
    # local gates: spacings that vary several fold, so no cap of 3 median spacings
    return nearest_neighbours(g.u, g.v, params.k_neighbours,
                              0.0 if params.local_gates else g.spacing_px)


def decode_jointly(images: Sequence[Glyphs], decoder: CodewordDecoder, params: GridParams,
                   carried: Sequence[np.ndarray] | None = None) -> bool:
    """Give the glyphs of several images their cells in one pass (in place).

    ``carried``: per image, each glyph's cell carried from the previous frame (flat, -1
    none; :mod:`.track`).  If this frame's lattice and labels confirm every one of them, the
    glyphs take them and the window search is skipped; returns whether it was (else the
    frame was decoded in full).  A glyph's k-NN table is taken from ``neighbours`` when a
    worker thread already computed it.
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
    u = np.concatenate([g.u.astype(np.float64) + o for g, o in zip(images, offsets)])
    v = np.concatenate([g.v.astype(np.float64) for g in images])
    label = np.concatenate([g.label for g in images])
    conf = np.concatenate([g.confidence for g in images])
    groups = np.repeat(np.arange(len(images)), sizes)
    hints = [g.spacing_px for g in images if g.spacing_px > 0]
    # k-NN per image (within an image's 3 spacings: never across images), unless a
    # worker thread already did it; indices shifted to the joint numbering.
    dists, idxs = [], []
    start = 0
    for g, n in zip(images, sizes):
        dist, idx = g.neighbours if g.neighbours is not None else glyph_neighbours(g, params)
        dists.append(dist)
        idxs.append(idx + start)
        start += n
    grid = build_grid(u, v, params, max(hints) if hints else 0.0,
                      neighbours=(np.concatenate(dists), np.concatenate(idxs)))
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
