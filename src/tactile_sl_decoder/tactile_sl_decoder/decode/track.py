"""Cells carried from the previous frame, verified on this frame's lattice (no rclpy).

Labels are carried by :mod:`tactile_sl_decoder.classify.carry`; that module also matches
each glyph to the glyph at its predicted place one frame earlier (``source``).  A glyph can
then take that glyph's cell, but only after checks on *this* frame: its label must be the
pattern's symbol at the cell, and its lattice neighbours (found again in this frame by
:func:`~tactile_sl_decoder.decode.grid.build_grid`) must hold the neighbouring cells --
at least ``min_agree`` of them, and none another cell.  :func:`verify_carried_cells` gives
the glyphs that pass; the pipeline skips the window search only when every glyph of the
frame passes or was undecoded before (and none is new), so a doubt anywhere means a full
decode.  A jump by a whole spacing moves every carried cell by one: the labels no longer
match the pattern there (the M-array's windows differ in >= 3 cells) and the frame is
decoded in full; a sudden press leaves glyphs without a match, likewise.
"""
from __future__ import annotations

import numpy as np

from tactile_sl_decoder.contract import LABEL_UNKNOWN
from tactile_sl_decoder.decode.grid import CENTRE, OFFSETS

_OTHERS = np.array([o for o in range(9) if o != CENTRE])


def carried_cells(source: np.ndarray, prev_row: np.ndarray, prev_col: np.ndarray,
                  cols: int) -> np.ndarray:
    """Flat cell (row * cols + col) of each glyph's previous-frame glyph, or -1."""
    source = np.asarray(source, np.int64)
    prev = np.where(prev_row >= 0, prev_row.astype(np.int64) * cols + prev_col, -1)
    has = source >= 0
    out = np.full(len(source), -1, np.int64)
    out[has] = prev[source[has]]
    return out


def verify_carried_cells(nbr: np.ndarray, cell: np.ndarray, label: np.ndarray,
                         confidence: np.ndarray, pattern: np.ndarray, mirrored: bool = False,
                         min_agree: int = 2, min_confidence: float = 0.5,
                         groups: np.ndarray | None = None) -> np.ndarray:
    """Which glyphs' carried cells this frame confirms (bool (N,); False where cell < 0).

    ``nbr`` (N, 9): this frame's lattice neighbour table (image orientation, -1 = none);
    ``cell`` (N,): carried flat cells, -1 = none; ``label`` / ``confidence``: this frame's
    labels; ``pattern`` (rows, cols): the printed symbols.  ``mirrored``: the cameras see
    the artwork mirrored (image columns run opposite to pattern columns).  ``groups``:
    the image of each glyph when several are checked at once (cells are unique per image).
    """
    rows, cols = pattern.shape
    n = len(cell)
    cell = np.asarray(cell, np.int64)
    has = cell >= 0
    safe = np.maximum(cell, 0)
    r, c = safe // cols, safe % cols
    known = (label != LABEL_UNKNOWN) & (confidence >= min_confidence)
    ok = has & known & (pattern[r, c] == label)
    # Lattice neighbours: neighbour (dr, dc) of a glyph at cell (r, c) must hold
    # (r + dr, c +- dc), or no cell; enough of them must hold it.
    dc_sign = -1 if mirrored else 1
    others = nbr[:, _OTHERS]                                  # (N, 8)
    has_nbr = others >= 0
    ncell = np.where(has_nbr, np.append(cell, -1)[np.where(has_nbr, others, n)], -1)
    er = r[:, None] + OFFSETS[_OTHERS, 0][None, :]
    ec = c[:, None] + dc_sign * OFFSETS[_OTHERS, 1][None, :]
    inside = (er >= 0) & (er < rows) & (ec >= 0) & (ec < cols)
    expected = np.where(inside, er * cols + ec, -2)
    decided = ncell >= 0
    agree = (decided & (ncell == expected)).sum(axis=1)
    disagree = (decided & (ncell != expected)).sum(axis=1)
    ok &= (agree >= min_agree) & (disagree == 0)
    # a cell carried to two glyphs: neither is confirmed
    key = safe if groups is None else np.asarray(groups, np.int64) * (rows * cols) + safe
    claims = np.bincount(key[has], minlength=int(key.max()) + 1 if n else 0)
    ok &= ~(has & (claims[key] > 1))
    return ok
