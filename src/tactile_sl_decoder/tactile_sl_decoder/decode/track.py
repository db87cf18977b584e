"""Cells carried from the previous frame (no rclpy).

Labels are carried by :mod:`tactile_sl_decoder.classify.carry`; that module also matches
each glyph to the glyph at its predicted place one frame earlier (``source``).  A glyph can
then take that glyph's cell (:func:`carried_cells`), but only after checks on *this* frame
(:meth:`~tactile_sl_decoder.decode.codewords.CodewordDecoder.confirm`): its label must be
the pattern's symbol at the cell, and its lattice neighbours (found again in this frame by
:func:`~tactile_sl_decoder.decode.grid.build_grid`) must hold the neighbouring cells -- at
least two of them, and none another cell.  The pipeline skips the window search only when
every glyph of the frame is confirmed or was undecoded before (and none is new), so a doubt
anywhere means a full decode.  A jump by a whole spacing moves every carried cell by one:
the labels no longer match the pattern there (the M-array's windows differ in >= 3 cells)
and the frame is decoded in full; a sudden press leaves glyphs without a match, likewise.
"""
from __future__ import annotations

import numpy as np


def carried_cells(source: np.ndarray, prev_row: np.ndarray, prev_col: np.ndarray,
                  cols: int) -> np.ndarray:
    """Flat cell (row * cols + col) of each glyph's previous-frame glyph, or -1."""
    source = np.asarray(source, np.int64)
    prev = np.where(prev_row >= 0, prev_row.astype(np.int64) * cols + prev_col, -1)
    has = source >= 0
    out = np.full(len(source), -1, np.int64)
    out[has] = prev[source[has]]
    return out
