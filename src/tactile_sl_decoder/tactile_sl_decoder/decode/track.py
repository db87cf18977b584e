"""Cells carried from the previous frame, and what a camera stream keeps of it (no rclpy).

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

:class:`StreamMemory` is what the pipeline keeps between two frames of a camera stream: per
camera the label carry and the cells decoded, and when the next full decode is due.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from tactile_sl_decoder.classify.carry import CarryParams, LabelCarry
from tactile_sl_decoder.glyphs import Glyphs


def carried_cells(source: np.ndarray, prev_row: np.ndarray, prev_col: np.ndarray,
                  cols: int) -> np.ndarray:
    """Flat cell (row * cols + col) of each glyph's previous-frame glyph, or -1."""
    source = np.asarray(source, np.int64)
    prev = np.where(prev_row >= 0, prev_row.astype(np.int64) * cols + prev_col, -1)
    has = source >= 0
    out = np.full(len(source), -1, np.int64)
    out[has] = prev[source[has]]
    return out


class StreamMemory:
    """The previous frame of a stereo camera stream: per camera its labels and cells.

    Both cameras' :class:`LabelCarry` share ``params`` (live changes apply to both); the
    cells of each camera's glyphs are kept for :func:`carried_cells`; every
    ``refresh_frames`` frames the next frame is decoded in full regardless.
    """

    def __init__(self, params: CarryParams) -> None:
        self.params = params
        self.carries = (LabelCarry(params), LabelCarry(params))
        self.cells: list[tuple[np.ndarray, np.ndarray] | None] = [None, None]
        self.full_decode_in = 0      # frames until the window search runs regardless

    def label_carries(self) -> tuple[LabelCarry | None, LabelCarry | None]:
        """The two cameras' label carries, or None when carrying is off (then forgotten)."""
        if self.params.enabled:
            return self.carries
        self.forget()
        return None, None

    def forget(self) -> None:
        """Nothing carried to the next frame: it is classified and decoded in full."""
        for c in self.carries:
            c.reset()
        self.cells = [None, None]
        self.full_decode_in = 0

    def carried_cells(self, images: Sequence[Glyphs], cols: int,
                      matches: Sequence[Any] | None = None) -> list[np.ndarray] | None:
        """Cells carried from the previous frame per image, or None: decode in full.

        In full when cells are not carried, every ``refresh_frames`` frames, or when a glyph
        has no glyph of the previous frame at its place (new, or moved too far).
        ``matches``: each camera's match of these glyphs to its previous frame's glyphs
        (default: this memory's label carries' latest, :attr:`LabelCarry.last`; a camera
        worker process keeps its carry and sends its match).
        """
        p = self.params
        if not (p.enabled and p.cells) or self.full_decode_in <= 0:
            return None
        if matches is None:
            matches = [carry.last for carry in self.carries]
        out = []
        for g, last, prev in zip(images, matches, self.cells):
            if prev is None or last is None or len(last.source) != len(g) or np.any(
                    last.source < 0):
                return None
            out.append(carried_cells(last.source, prev[0], prev[1], cols))
        return out

    def remember(self, images: Sequence[Glyphs], tracked: bool) -> None:
        """This frame's cells; a full decode (not ``tracked``) restarts the countdown."""
        self.cells = [(g.row, g.col) for g in images]
        self.full_decode_in = (self.full_decode_in - 1 if tracked
                               else self.params.refresh_frames - 1)
