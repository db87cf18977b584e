"""Codeword decoding: the pattern cell of each glyph, from its window (no rclpy).

The printed M-array has the property that every ``wr x wc`` window of symbols differs from
every other window in at least ``h = min_hamming`` cells.  A glyph's cell is therefore
determined by the labels of its window, and up to ``floor((h - 1) / 2)`` misclassified
cells (or ``h - 1`` unknown ones) can be corrected.

Decoding is a table look-up, fully vectorised:

* Windows are encoded as integers in base ``k + 1`` (digit ``k`` = unknown / missing).
* :class:`Codebook` precomputes every observable code within the correction radius of each
  pattern window (all substitution / erasure patterns with ``2e + u < h``), mapped to the
  window's anchor cell; codes reachable from two windows (only if the pattern violates its
  own ``min_hamming``) are marked ambiguous and never decode.
* A window that does not decode is retried with its least confident label erased
  (confidences break the tie between "one more error" and "one more unknown").

Because a wrong cell is far worse than a missing one, a decoded window alone does not give a
glyph its cell.  Every decoded window *votes* a cell for each glyph it covers (glyph at
window position (a, b) of a window anchored at cell (r, c) gets cell (r - r0 + a, c - c0 + b));
a glyph is accepted only with enough votes and a clear majority, its accepted lattice
neighbours must hold the neighbouring cells, no cell may be claimed twice, and finally
undecided glyphs are grown from agreeing decided neighbours when their own label matches.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations, product

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.spatial import cKDTree

from tactile_sl_common.settings import SettingsTable
from tactile_sl_decoder.contract import CELL_UNKNOWN, LABEL_UNKNOWN
from tactile_sl_decoder.decode.grid import NEIGHBOUR_SLOTS, OFFSETS, Grid, window_indices
from tactile_sl_decoder.decode.votes import confirmed_cells, group_votes, linked_regions

DIRECT_TABLE_MAX = 1 << 22   # code spaces up to this size are looked up by direct address


class PatternError(ValueError):
    """A pattern array / window / min_hamming combination that cannot be decoded."""


@dataclass
class DecodeParams:
    """Thresholds of codeword decoding and of the consistency checks."""

    min_confidence: float = 0.5
    """Labels below this confidence count as unknown."""
    max_errors: int = -1
    """Substitutions corrected per window; -1: (h - 1) // 2."""
    max_erasures: int = -1
    """Unknown cells tolerated per window (no errors); -1: h - 1."""
    retry_confidence: float = 0.9
    """Erase the least confident label (if below this) and retry."""
    min_votes: int = 2
    """Agreeing window decodes needed before a glyph gets a cell."""
    vote_ratio: float = 0.7
    """The winning cell's share of all votes for the glyph."""
    grow_iterations: int = 12
    """Passes extending decoded regions to undecided glyphs."""
    grow_min_agree: int = 2
    """Decided neighbours that must agree to grow a glyph ..."""
    grow_min_agree_mismatch: int = 4
    """... when its own label contradicts that cell."""
    min_component: int = 16
    """Smallest region of mutually consistent decoded glyphs that is kept."""
    island_check_px: float = 4.0
    """Islands near the main region must fit it (x spacing)."""
    mirrored: bool = False
    """The cameras see the artwork mirrored (looking through the elastomer): columns
    reversed."""


DECODE_SETTINGS = SettingsTable(DecodeParams, fields=("mirrored", "min_votes", "min_component"),
                                ranges={"min_votes": (1, 100), "min_component": (1, 100000)})
"""The decoder node's live ``mirrored``, ``min_votes`` and ``min_component`` parameters."""


@dataclass
class Decoded:
    """Per-glyph decoding result (arrays of length N)."""

    row: np.ndarray          # int32, -1 unknown
    col: np.ndarray          # int32, -1 unknown
    votes: np.ndarray        # int32, agreeing votes for the accepted cell (0 if grown/none)
    windows_decoded: int     # windows that decoded (before consistency)

    @property
    def decoded(self) -> np.ndarray:
        """Boolean mask of glyphs with a cell."""
        return self.row >= 0


class Codebook:
    """All windows of a pattern array and their correctable neighbourhoods.

    ``array`` is the pattern (rows x cols, values 0..k-1); ``window`` (wr, wc); the anchor
    of a window is its cell (wr // 2, wc // 2), so a window anchored at cell (r, c) covers
    rows r - wr // 2 ... and columns c - wc // 2 ...
    """

    def __init__(self, array: np.ndarray, window: tuple[int, int] = (3, 3),
                 min_hamming: int = 3, symbols: int | None = None,
                 max_errors: int = -1, max_erasures: int = -1) -> None:
        arr = np.asarray(array)
        if arr.ndim != 2:
            raise PatternError(f"pattern array must be 2-D, got shape {arr.shape}")
        wr, wc = int(window[0]), int(window[1])
        if wr < 1 or wc < 1 or wr > arr.shape[0] or wc > arr.shape[1]:
            raise PatternError(f"window {wr}x{wc} does not fit the {arr.shape} pattern")
        k = int(symbols) if symbols is not None else int(arr.max()) + 1
        if arr.min() < 0 or arr.max() >= k:
            raise PatternError(f"pattern values must be 0..{k - 1}")
        h = int(min_hamming)
        if h < 1:
            raise PatternError("min_hamming must be at least 1")
        self.array = arr.astype(np.int64)
        self.rows, self.cols = arr.shape
        self.window = (wr, wc)
        self.anchor = (wr // 2, wc // 2)
        self.symbols = k
        self.min_hamming = h
        self.n = wr * wc
        self.base = k + 1
        if self.n * np.log2(self.base) > 62:
            raise PatternError("window too large to encode as a 64-bit integer")
        self.max_errors = (h - 1) // 2 if max_errors < 0 else min(max_errors, (h - 1) // 2)
        self.max_erasures = h - 1 if max_erasures < 0 else min(max_erasures, h - 1)
        self.weights = self.base ** np.arange(self.n, dtype=np.int64)

        # All windows, (M, n) row-major, and their anchor cells.
        win = sliding_window_view(self.array, (wr, wc)).reshape(-1, self.n)
        nr, nc = self.rows - wr + 1, self.cols - wc + 1
        ar, ac = np.meshgrid(np.arange(nr) + self.anchor[0], np.arange(nc) + self.anchor[1],
                             indexing="ij")
        self.windows = win
        self.window_cells = (ar * self.cols + ac).reshape(-1)
        exact = win @ self.weights
        if len(np.unique(exact)) != len(exact):
            raise PatternError("pattern has repeated windows: cells are not unique")
        self._build_table()

    def _build_table(self) -> None:
        """Every code within the correction radius -> anchor cell (-1 if ambiguous)."""
        n, k, unknown = self.n, self.symbols, self.symbols
        base_codes = self.windows @ self.weights                    # (M,)
        keys, cells, costs = [base_codes], [self.window_cells], [np.zeros(len(base_codes))]
        h = self.min_hamming
        for e in range(0, self.max_errors + 1):
            for u in range(0, self.max_erasures + 1):
                if e + u == 0 or 2 * e + u >= h:
                    continue
                for pos in combinations(range(n), e + u):
                    sub_pos, era_pos = pos[:e], pos[e:]
                    # For substitutions, every other symbol at each position: shifts 1..k-1.
                    for shifts in product(range(1, k), repeat=e):
                        w = self.windows.copy()
                        for p, s in zip(sub_pos, shifts):
                            w[:, p] = (w[:, p] + s) % k
                        for p in era_pos:
                            w[:, p] = unknown
                        keys.append(w @ self.weights)
                        cells.append(self.window_cells)
                        costs.append(np.full(len(w), e + 0.5 * u))
        key = np.concatenate(keys)
        cell = np.concatenate(cells)
        cost = np.concatenate(costs)
        order = np.argsort(key, kind="stable")
        key, cell, cost = key[order], cell[order], cost[order]
        uniq, start, count = np.unique(key, return_index=True, return_counts=True)
        out_cell = cell[start].copy()
        out_cost = cost[start].copy()
        # A code reachable from two different windows is ambiguous: never decode it.
        multi = np.flatnonzero(count > 1)
        if len(multi):
            cmin = np.minimum.reduceat(cell, start)
            cmax = np.maximum.reduceat(cell, start)
            out_cell[cmin != cmax] = -1
        self.table_keys = uniq
        self.table_cells = out_cell
        self.table_costs = out_cost
        # Small code spaces (3 symbols, 3x3: 4^9 = 262,144 codes) get a direct-address
        # table: one gather per look-up instead of a binary search.
        self.direct_cells: np.ndarray | None = None
        if self.base ** self.n <= DIRECT_TABLE_MAX:
            self.direct_cells = np.full(self.base ** self.n, -1, dtype=np.int64)
            self.direct_cells[uniq] = out_cell

    def lookup(self, codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Anchor cell index (row * cols + col, -1 if none) and correction cost per code."""
        codes = np.asarray(codes, dtype=np.int64)
        if self.direct_cells is not None:
            cell = self.direct_cells[codes]
            pos = np.searchsorted(self.table_keys, codes)
            pos = np.minimum(pos, len(self.table_keys) - 1)
            return cell, np.where(cell >= 0, self.table_costs[pos], np.inf)
        pos = np.searchsorted(self.table_keys, codes)
        pos = np.minimum(pos, len(self.table_keys) - 1)
        hit = self.table_keys[pos] == codes
        cell = np.where(hit, self.table_cells[pos], -1)
        cost = np.where(cell >= 0, self.table_costs[pos], np.inf)
        return cell, cost

    def _cells(self, codes: np.ndarray) -> np.ndarray:
        """Anchor cell per code (-1 if none): :meth:`lookup` without the costs."""
        if self.direct_cells is not None:
            return self.direct_cells[codes]
        return self.lookup(codes)[0]

    def decode_windows(self, labels: np.ndarray, confidence: np.ndarray,
                       retry_confidence: float = 0.9) -> np.ndarray:
        """Anchor cell per window (M, n) of labels (``k`` or more = unknown), -1 if none.

        A window that does not decode within the correction radius is retried with its
        least confident known label turned into an unknown, if that confidence is below
        ``retry_confidence``.
        """
        labels = np.asarray(labels, dtype=np.int64)
        lab = np.where((labels < 0) | (labels >= self.symbols), self.symbols, labels)
        cell = self._cells(lab @ self.weights)
        fail = np.flatnonzero(cell < 0)
        if len(fail):
            conf = np.where(lab[fail] == self.symbols, np.inf, confidence[fail])
            weakest = np.argmin(conf, axis=1)
            weak_conf = conf[np.arange(len(fail)), weakest]
            retry = fail[weak_conf < retry_confidence]
            if len(retry):
                lab2 = lab[retry].copy()
                lab2[np.arange(len(retry)), weakest[weak_conf < retry_confidence]] = self.symbols
                cell[retry] = self._cells(lab2 @ self.weights)
        return cell


_DR = OFFSETS[NEIGHBOUR_SLOTS, 0]
_DC = OFFSETS[NEIGHBOUR_SLOTS, 1]


@dataclass
class _Layout:
    """Cell numbering used inside the decoder: padded, one block per image (group).

    Cell (g, r, c) is ``(g * H + r + 1) * W + c + 1`` with H = rows + 2, W = cols + 2, so the
    neighbouring cell at (dr, dc) is a constant offset away and the one-cell padding tells
    "outside the pattern" by table look-up: no integer division in the hot loops.
    """

    rows: int
    cols: int
    groups: int

    def __post_init__(self) -> None:
        self.H, self.W = self.rows + 2, self.cols + 2
        self.size = self.groups * self.H * self.W
        self.delta = _DR * self.W + _DC                      # (8,) offsets of the neighbours
        valid = np.zeros((self.groups, self.H, self.W), dtype=bool)
        valid[:, 1:-1, 1:-1] = True
        self.valid = valid.reshape(-1)
        # valid, plus W + 2 False entries: the "implied cell" -1 - delta of an unknown
        # neighbour (-W - 2 .. W) then indexes padding or that tail, never a valid cell.
        self.valid_ext = np.concatenate([self.valid, np.zeros(self.W + 2, dtype=bool)])

    def encode(self, group: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """Internal cell numbers."""
        return (group * self.H + row + 1) * self.W + col + 1

    def split(self, cell: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(group, row, col) of internal cell numbers."""
        gr, c = np.divmod(cell, self.W)
        g, r = np.divmod(gr, self.H)
        return g, r - 1, c - 1

    def values(self, array: np.ndarray) -> np.ndarray:
        """Pattern value of every internal cell (-1 in the padding)."""
        out = np.full((self.groups, self.H, self.W), -1, dtype=np.int64)
        out[:, 1:-1, 1:-1] = array[None]
        return out.reshape(-1)


def _links(nbr: np.ndarray) -> np.ndarray:
    """The 8 neighbours of every glyph, (N, 8), N where there is none (a sentinel slot)."""
    j = nbr[:, NEIGHBOUR_SLOTS]
    return np.where(j >= 0, j, len(nbr))


class CodewordDecoder:
    """Glyph labels + lattice -> pattern cells, with voting and consistency checks."""

    def __init__(self, codebook: Codebook, params: DecodeParams | None = None) -> None:
        self.codebook = codebook
        self.params = params or DecodeParams()
        # per image count: the cell layout and the pattern value of every internal cell,
        # built once and reused across frames (read-only)
        self._layouts: dict[tuple[int, int], tuple[_Layout, np.ndarray]] = {}

    def _layout(self, groups: int) -> tuple[_Layout, np.ndarray]:
        """Cell layout for ``groups`` images and the pattern value of each of its cells."""
        cb = self.codebook
        key = (id(cb), groups)
        if key not in self._layouts:
            lay = _Layout(cb.rows, cb.cols, groups)
            if len(self._layouts) >= 4:
                self._layouts.clear()
            self._layouts[key] = (lay, lay.values(cb.array))
        return self._layouts[key]

    def decode(self, grid: Grid, labels: np.ndarray, confidence: np.ndarray,
               groups: np.ndarray | None = None) -> Decoded:
        """Decode every glyph of one image (labels 255 = unknown).

        Several images can be decoded in one call (cheaper than one call each: the cost is
        mostly per numpy operation, not per glyph): their glyphs must be far apart in the
        lattice (e.g. offset coordinates) and ``groups`` says which image each glyph is in.
        Cells are unique, and regions checked, per group.
        """
        cb, p = self.codebook, self.params
        n = grid.nbr.shape[0]
        groups = (np.zeros(n, dtype=np.int64) if groups is None
                  else np.asarray(groups, dtype=np.int64).reshape(-1))
        lay, values = self._layout(int(groups.max()) + 1 if n else 1)
        labels = np.asarray(labels).astype(np.int64).reshape(-1)
        confidence = np.asarray(confidence, dtype=np.float64).reshape(-1)
        row = np.full(n, CELL_UNKNOWN, dtype=np.int32)
        col = np.full(n, CELL_UNKNOWN, dtype=np.int32)
        votes_out = np.zeros(n, dtype=np.int32)
        if n == 0:
            return Decoded(row, col, votes_out, 0)
        nbr = grid.nbr
        if p.mirrored:   # image columns run opposite to pattern columns
            nbr = nbr.reshape(n, 3, 3)[:, :, ::-1].reshape(n, 9)
        pgrid = Grid(nbr, grid.col_vec, grid.row_vec, grid.spacing_px, grid.pts)
        widx = window_indices(pgrid, cb.window)                    # (N, n) glyph indices
        lab = np.where(confidence >= p.min_confidence, labels, LABEL_UNKNOWN)
        lab = np.where((lab >= 0) & (lab < cb.symbols), lab, cb.symbols)
        wl = np.where(widx >= 0, lab[np.maximum(widx, 0)], cb.symbols)
        wc_ = np.where(widx >= 0, confidence[np.maximum(widx, 0)], 0.0)
        # Windows with too many unknowns cannot decode anyway; skip them early.
        n_unknown = (wl == cb.symbols).sum(axis=1)
        todo = np.flatnonzero(n_unknown <= cb.max_erasures + 1)
        anchor_cell = np.full(n, -1, dtype=np.int64)
        if len(todo):
            anchor_cell[todo] = cb.decode_windows(wl[todo], wc_[todo], p.retry_confidence)
        ok = np.flatnonzero(anchor_cell >= 0)
        windows_decoded = len(ok)

        # Votes: every decoded window assigns a cell to each glyph it covers.
        wr, wcw = cb.window
        a0, b0 = cb.anchor
        pos_r = np.repeat(np.arange(wr), wcw) - a0                 # (n,)
        pos_c = np.tile(np.arange(wcw), wr) - b0
        ar, ac = anchor_cell[ok] // cb.cols, anchor_cell[ok] % cb.cols
        g = widx[ok]                                              # (K, n)
        anchor = lay.encode(groups[ok], ar, ac)
        vcell = anchor[:, None] + (pos_r * lay.W + pos_c)[None, :]   # internal numbering
        m = g >= 0
        gg, cc, top, total = group_votes(np.ascontiguousarray(g[m], dtype=np.int64),
                                         np.ascontiguousarray(vcell[m], dtype=np.int64))
        accept = (top >= p.min_votes) & (top >= p.vote_ratio * total)
        cell = np.full(n, -1, dtype=np.int64)
        cell[gg[accept]] = cc[accept]
        votes_out[gg[accept]] = top[accept]

        links = _links(pgrid.nbr)
        cell = self._consistency(pgrid.nbr, cell, lay, links)
        cell = self._islands(pgrid, cell, lay, links)
        grew = False
        for _ in range(p.grow_iterations):
            grown = self._grow(pgrid.nbr, cell, lab, lay, values, links)
            if not np.any(grown != cell):
                break
            grew = True
            cell = self._consistency(pgrid.nbr, grown, lay, links)
        if grew:
            cell = self._islands(pgrid, cell, lay, links)
        has = cell >= 0
        _, r, c = lay.split(cell[has])
        row[has] = r.astype(np.int32)
        col[has] = c.astype(np.int32)
        return Decoded(row, col, votes_out, windows_decoded)

    def confirm(self, grid: Grid, cell: np.ndarray, labels: np.ndarray,
                confidence: np.ndarray, groups: np.ndarray | None = None,
                min_agree: int = 2) -> np.ndarray:
        """Which glyphs this frame confirms in a given cell (bool (N,); False where -1).

        ``cell`` (N,): a candidate cell per glyph (flat ``row * cols + col`` of the pattern,
        -1 = none), e.g. carried from the previous frame (:mod:`.track`).  Confirmed: the
        glyph's label (known, confidence >= ``min_confidence``) is the pattern's symbol
        there, at least ``min_agree`` of its lattice neighbours hold candidates that imply
        the same cell and none implies another (the decoder's consistency rule), and no
        other glyph of its image has the same candidate.
        """
        cb, p = self.codebook, self.params
        n = grid.nbr.shape[0]
        groups = (np.zeros(n, dtype=np.int64) if groups is None
                  else np.asarray(groups, dtype=np.int64).reshape(-1))
        lay, values = self._layout(int(groups.max()) + 1 if n else 1)
        cell = np.asarray(cell, np.int64)
        has = cell >= 0
        internal = np.where(has, lay.encode(groups, cell // cb.cols, cell % cb.cols), -1)
        nbr = grid.nbr
        if p.mirrored:   # image columns run opposite to pattern columns
            nbr = nbr.reshape(n, 3, 3)[:, :, ::-1].reshape(n, 9)
        lab = np.where(np.asarray(confidence) >= p.min_confidence,
                       np.asarray(labels).astype(np.int64), -2)
        return confirmed_cells(np.ascontiguousarray(_links(nbr), dtype=np.int64),
                               np.ascontiguousarray(internal, dtype=np.int64), lab,
                               np.ascontiguousarray(values, dtype=np.int64),
                               np.ascontiguousarray(lay.delta, dtype=np.int64),
                               lay.valid_ext, int(min_agree), int(lay.size))

    @staticmethod
    def _expected(nbr: np.ndarray, cell: np.ndarray, lay: _Layout,
                  links: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Per glyph and 8-neighbour: the neighbour's cell and the cell it implies here.

        Both (N, 8) internal cell numbers, -1 where unknown or outside the pattern.
        ``links``: :func:`_links` of ``nbr``, if already computed.
        """
        if links is None:
            links = _links(nbr)
        cj = np.append(cell, -1)[links]             # -1: no neighbour or undecided
        implied = cj - lay.delta
        return cj, np.where(lay.valid_ext[implied], implied, -1)

    def _consistency(self, nbr: np.ndarray, cell: np.ndarray, lay: _Layout,
                     links: np.ndarray | None = None) -> np.ndarray:
        """Drop glyphs whose decided neighbours disagree with them, and duplicate cells."""
        cell = cell.copy()
        for _ in range(2):
            cj, implied = self._expected(nbr, cell, lay, links)
            known = (cj >= 0) & (cell[:, None] >= 0)
            agree = (known & (implied == cell[:, None])).sum(axis=1)
            disagree = (known & (implied != cell[:, None])).sum(axis=1)
            bad = (cell >= 0) & (disagree > 0) & (disagree >= agree)
            if not bad.any():
                break
            cell[bad] = -1
        # A cell claimed by two glyphs: at least one is wrong, drop both.
        has = np.flatnonzero(cell >= 0)
        claims = np.bincount(cell[has], minlength=lay.size)
        cell[has[claims[cell[has]] > 1]] = -1
        return cell

    def _islands(self, grid: Grid, cell: np.ndarray, lay: _Layout,
                 links: np.ndarray | None = None) -> np.ndarray:
        """Keep only sizeable, mutually consistent regions of decoded glyphs.

        Decoded glyphs linked by lattice neighbours holding the neighbouring cells form
        connected regions.  A region smaller than ``min_component`` is dropped (chance
        decodes are isolated), and a smaller region near the largest one must hold the cells
        the largest region's lattice predicts there, or it is dropped too (a locally
        consistent but misplaced patch, e.g. a misread that copies another pattern area).
        """
        p = self.params
        dec = np.flatnonzero(cell >= 0)
        if len(dec) == 0:
            return cell
        _, implied = self._expected(grid.nbr, cell, lay, links)
        ok = (implied == cell[:, None]) & (cell[:, None] >= 0)
        comp = linked_regions(np.ascontiguousarray(grid.nbr[:, NEIGHBOUR_SLOTS], dtype=np.int64),
                              np.ascontiguousarray(ok))
        sizes = np.bincount(comp[dec], minlength=comp.max() + 1)
        keep = sizes[comp] >= p.min_component
        # The largest region of each image (group) is the reference for its other regions.
        dec_group = lay.split(cell[dec])[0]
        is_main = np.zeros(len(sizes), dtype=bool)
        for grp in range(lay.groups):
            in_grp = comp[dec[dec_group == grp]]
            if len(in_grp):
                is_main[np.argmax(np.bincount(in_grp, minlength=len(sizes)))] = True
        if grid.pts is not None and grid.spacing_px > 0 and not is_main.all():
            main_dec = is_main[comp[dec]] & (sizes[comp[dec]] >= p.min_component)
            others_dec = dec[~is_main[comp[dec]] & keep[dec]]
            main_idx = dec[main_dec]
            if len(others_dec) and len(main_idx):
                tree = cKDTree(grid.pts[main_idx])
                dist, nn = tree.query(grid.pts[others_dec],
                                      distance_upper_bound=p.island_check_px * grid.spacing_px)
                near = np.isfinite(dist)
                a = others_dec[near]
                b = main_idx[nn[near]]
                M = np.stack([grid.col_vec[b], grid.row_vec[b]], axis=2)   # (K, 2, 2)
                d = grid.pts[a] - grid.pts[b]
                with np.errstate(all="ignore"):
                    steps = np.linalg.solve(M + 1e-12 * np.eye(2), d[..., None])[..., 0]
                dc = np.rint(steps[:, 0]).astype(np.int64) * (-1 if p.mirrored else 1)
                dr = np.rint(steps[:, 1]).astype(np.int64)
                pred = cell[b] + dr * lay.W + dc
                agree = pred == cell[a]
                votes_ok = np.bincount(comp[a], weights=agree, minlength=len(sizes))
                votes_all = np.bincount(comp[a], minlength=len(sizes))
                bad_comp = (votes_all > 0) & (votes_ok < 0.5 * votes_all)
                keep &= ~bad_comp[comp]
        out = cell.copy()
        out[~keep] = -1
        return out

    def _grow(self, nbr: np.ndarray, cell: np.ndarray, lab: np.ndarray, lay: _Layout,
              values: np.ndarray, links: np.ndarray | None = None) -> np.ndarray:
        """Give undecided glyphs the cell implied by agreeing decided neighbours.

        All decided neighbours must agree, the cell must be free, and more of them are needed
        when the glyph's label is unknown or contradicts the pattern there.
        """
        p, cb = self.params, self.codebook
        _, implied = self._expected(nbr, cell, lay, links)
        undecided = cell < 0
        imp = np.where(undecided[:, None], implied, -1)
        srt = np.sort(imp, axis=1)
        top = srt[:, -1]
        n_top = (imp == top[:, None]).sum(axis=1)
        n_any = (imp >= 0).sum(axis=1)
        label_known = lab < cb.symbols
        pattern_val = np.where(top >= 0, values[np.maximum(top, 0)], -1)
        # Agreeing neighbours needed: fewer when the glyph's own label confirms the cell,
        # more when it is unknown, most when it contradicts it (a misclassified glyph whose
        # place in the lattice is certain still gets its cell).
        need = np.where(~label_known, p.grow_min_agree + 1,
                        np.where(pattern_val == lab, p.grow_min_agree, p.grow_min_agree_mismatch))
        ok = undecided & (top >= 0) & (n_top == n_any) & (n_top >= need)
        taken = np.zeros(lay.size, dtype=bool)
        taken[cell[cell >= 0]] = True
        ok &= ~taken[np.maximum(top, 0)]
        out = cell.copy()
        out[ok] = top[ok]
        return out
