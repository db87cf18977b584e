"""Cells carried across the stereo pair, where one camera could not decode its glyphs.

A glyph one camera could not decode takes the cell the other camera decoded at the place
the pair's geometry predicts. Where one camera sees the pad badly (its own vignetting
corner, a darker exposure, dust on its lens) its glyphs there are found but read too
poorly for the 3 x 3 codeword windows, while the other camera decoded the same cells. A
cell ``C`` decoded in the *source* image but not in the *target* image is looked for in the
target at

    rect_target(C) ~= rect_source(C) + median_N (rect_target(N) - rect_source(N))

over the lattice neighbours ``N`` of ``C`` (8-neighbourhood of cells) that both images
decoded: the disparity field of a smooth surface varies little from one glyph to the next,
so the prediction misses by a fraction of a pixel even on a pressed sphere, while the next
glyph lies a whole spacing away. The target glyph nearest the prediction takes ``C`` only
if

* it lies within ``radius`` glyph spacings of the prediction and no other target glyph lies
  within ``clearance`` spacings of it (a spurious blob or a merged pair makes it doubtful);
* it has no cell yet, and its label is unknown or the pattern's symbol of ``C`` (a
  confident other symbol contradicts the cell);
* at least ``min_neighbours`` neighbours of ``C`` are decoded in both images, and their
  offsets agree (spread below ``radius`` spacings);
* no other cell claims the same glyph in that pass.

Cells are grown outwards pass by pass (a transferred cell is a neighbour in the next pass),
both ways (left -> right, right -> left). The points of transferred cells then meet the same
stereo and surface-outlier gates as any other (:meth:`StereoPipeline.triangulate`). The
prediction is that of area-based stereo with a smoothness prior (D. Scharstein and R.
Szeliski, "A taxonomy and evaluation of dense two-frame stereo correspondence
algorithms", IJCV 47, 2002, sec. 3: disparity propagation from reliable matches), applied to
the codeword's cells rather than to pixels.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from tactile_sl_common.settings import SettingsTable
from tactile_sl_decoder.contract import CELL_UNKNOWN, LABEL_UNKNOWN
from tactile_sl_decoder.glyphs import Glyphs


@dataclass
class TransferParams:
    """Settings of :func:`transfer_cells` (the decoder node's ``transfer.*`` parameters)."""

    enabled: bool = True
    """A glyph one image could not decode takes the cell the other image decoded where the
    pair's geometry and the neighbouring cells put it."""
    radius: float = 0.2
    """Largest distance of the target glyph from the predicted place (and spread of the
    neighbours' predictions), glyph spacings."""
    clearance: float = 0.55
    """No other target glyph may lie this close (glyph spacings) to the chosen one (checked
    as: the second-nearest glyph lies ``clearance`` + the chosen one's distance away from
    the prediction)."""
    min_neighbours: int = 2
    """Neighbouring cells decoded in both images needed to predict a cell's place."""
    passes: int = 8
    """Growth passes (each can add cells next to those the last one added; 0 = off)."""

    def validate(self) -> "TransferParams":
        """Raise ValueError naming the first setting outside :data:`TRANSFER_SETTINGS`."""
        TRANSFER_SETTINGS.check(self, "transfer.")
        return self


TRANSFER_SETTINGS = SettingsTable(TransferParams, ranges={
    "radius": (0.01, 0.45), "clearance": (0.1, 1.0), "min_neighbours": (1, 8),
    "passes": (0, 64)})
"""The decoder node's live ``transfer.<field>`` parameters."""


# the 8 cell offsets of a cell's lattice neighbourhood
NEIGHBOUR_STEPS = np.array([(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                             if dr or dc], np.int64)


def transfer_cells(left: Glyphs, right: Glyphs, rect_left: np.ndarray, rect_right: np.ndarray,
                   symbols: np.ndarray, params: TransferParams | None = None) -> int:
    """Give undecoded glyphs of each image the cell the other image decoded there.

    ``rect_left`` / ``rect_right``: (N, 2) rectified pixels of every glyph of each image;
    ``symbols``: (rows, cols) the pattern's symbol of every cell. ``left.row`` / ``col`` and
    ``right.row`` / ``col`` are updated in place. Returns the number of cells transferred.
    """
    p = params or TransferParams()
    if not p.enabled or p.passes <= 0 or len(left) == 0 or len(right) == 0:
        return 0
    if not needs_transfer(left, right):
        return 0
    known = [g.spacing_px for g in (left, right) if g.spacing_px > 0]
    spacing = float(sum(known) / len(known)) if known else 0.0
    if spacing <= 0:
        return 0
    sides = [_Side(left, rect_left, symbols.shape), _Side(right, rect_right, symbols.shape)]
    done = 0
    for _ in range(int(p.passes)):
        added = (_one_way(sides[0], sides[1], symbols, spacing, p)
                 + _one_way(sides[1], sides[0], symbols, spacing, p))
        done += added
        if not added:
            break
    return done


def needs_transfer(left: Glyphs, right: Glyphs) -> bool:
    """Whether a glyph of either image lacks a cell (the usual frame: none does)."""
    return bool((left.row == CELL_UNKNOWN).any() or (right.row == CELL_UNKNOWN).any())


def cell_table(g: Glyphs, shape: tuple[int, int]) -> np.ndarray:
    """(rows + 2, cols + 2) index of the glyph holding each cell, -1 none.

    One cell of padding all round, so that every cell's 8 neighbours can be looked up.
    """
    table = np.full((shape[0] + 2, shape[1] + 2), -1, np.int64)
    ok = np.flatnonzero((g.row != CELL_UNKNOWN) & (g.row < shape[0]) & (g.col < shape[1]))
    table[g.row[ok] + 1, g.col[ok] + 1] = ok
    return table


def predict_missing(pos_src: np.ndarray, ts: np.ndarray, pos_dst: np.ndarray,
                    td: np.ndarray, min_neighbours: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the target image should show the cells only the source image holds.

    ``ts`` / ``td``: padded cell tables (:func:`cell_table`) of the source and target
    images, ``pos_src`` / ``pos_dst`` their glyphs' positions (any pixel convention, the
    same in both). For each cell the source holds and the target does not, with at least
    ``min_neighbours`` of its 8 lattice neighbours held by both: the cell (row, col), its
    predicted target position (its source position plus the median offset target - source
    of those neighbours) and the spread of those offsets about the median (largest
    distance). Used by :func:`transfer_cells` and :mod:`.rescue`.
    """
    none = (np.zeros((0, 2), np.int64), np.zeros((0, 2)), np.zeros(0))
    missing = np.argwhere((ts >= 0) & (td < 0))                 # padded (row, col)
    if len(missing) == 0:
        return none
    rr = missing[:, 0:1] + NEIGHBOUR_STEPS[None, :, 0]
    cc = missing[:, 1:2] + NEIGHBOUR_STEPS[None, :, 1]
    ns, nd = ts[rr, cc], td[rr, cc]
    have = (ns >= 0) & (nd >= 0)                                 # (M, 8)
    keep = have.sum(axis=1) >= int(min_neighbours)
    if not keep.any():
        return none
    missing, ns, nd, have = missing[keep], ns[keep], nd[keep], have[keep]
    near = pos_dst[nd] - pos_src[ns]                             # (M, 8, 2), valid where have
    shift = median_rows(near, have)                             # (M, 2)
    # the largest distance, as the square root of the largest squared distance (the same
    # value: the square root is monotonic and correctly rounded), one root per cell
    d = near - shift[:, None, :]
    spread = np.sqrt(np.where(have, d[:, :, 0] * d[:, :, 0] + d[:, :, 1] * d[:, :, 1],
                              0.0).max(axis=1))
    predicted = pos_src[ts[missing[:, 0], missing[:, 1]]] + shift
    return missing - 1, predicted, spread


class _Side:
    """One image's glyphs with its cell table and (built when first needed) k-d tree."""

    def __init__(self, glyphs: Glyphs, rect: np.ndarray, shape: tuple[int, int]) -> None:
        self.glyphs, self.rect = glyphs, np.asarray(rect, np.float64)
        self.table = cell_table(glyphs, shape)
        self._tree: cKDTree | None = None
        self.undecoded = int((glyphs.row == CELL_UNKNOWN).sum())  # glyphs a cell could go to

    @property
    def tree(self) -> cKDTree:
        if self._tree is None:
            self._tree = cKDTree(self.rect)
        return self._tree


def median_rows(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Median of each row's valid entries, per last axis: (M, K, D), (M, K) -> (M, D).

    A sort with the invalid entries last (np.nanmedian goes through masked arrays: ~1 ms).
    """
    x = np.sort(np.where(valid[:, :, None], values, np.inf), axis=1)
    count = valid.sum(axis=1)
    row = np.arange(len(x))
    return 0.5 * (x[row, (count - 1) // 2] + x[row, count // 2])


def _one_way(src: _Side, dst: _Side, symbols: np.ndarray, spacing: float,
             p: TransferParams) -> int:
    """One pass of cells decoded in ``src`` given to glyphs of ``dst``; returns the count."""
    if dst.undecoded == 0:
        return 0
    missing, predicted, spread = predict_missing(src.rect, src.table, dst.rect, dst.table,
                                                 p.min_neighbours)
    if len(missing) == 0:
        return 0
    dist, idx = dst.tree.query(predicted, k=2)
    first, chosen, second = dist[:, 0], idx[:, 0], dist[:, 1]
    g = dst.glyphs
    symbol = symbols[missing[:, 0], missing[:, 1]]
    label = g.label[chosen]
    ok = ((first <= p.radius * spacing) & (spread <= p.radius * spacing)
          & (second >= p.clearance * spacing + first)
          & (g.row[chosen] == CELL_UNKNOWN)
          & ((label == LABEL_UNKNOWN) | (label == symbol)))
    # a glyph claimed by two cells takes neither
    claims = np.bincount(chosen[ok], minlength=len(g))
    ok &= claims[chosen] == 1
    if not ok.any():
        return 0
    rows, cols, glyph = missing[ok, 0], missing[ok, 1], chosen[ok]
    g.row[glyph] = rows
    g.col[glyph] = cols
    dst.table[rows + 1, cols + 1] = glyph
    dst.undecoded -= len(glyph)
    return len(glyph)
