"""Labels carried from the previous frame: classify only the glyphs that need it (no rclpy).

At 30-60 Hz consecutive frames of one camera differ by a fraction of a glyph spacing, so
most glyphs sit where a glyph sat one frame earlier and look the same.  Such a glyph keeps
that glyph's label instead of going through the classifier, which is the largest share of a
frame's unavoidable work.  A glyph keeps a label only when *all* of these hold:

* the previous glyph was labelled with confidence >= ``min_confidence`` (doubtful labels are
  classified again);
* the previous glyph's predicted position (its position one frame earlier plus the step it
  made then: constant velocity) is the nearest one to it, within ``radius`` glyph spacings,
  and no other glyph of this frame has that one as its nearest;
* its patch correlates with the previous glyph's patch by at least ``min_correlation``
  (the correlation coefficient of template matching, J. P. Lewis, "Fast Normalized
  Cross-Correlation", Vision Interface 1995, over the central part of the patch where the
  glyph is).  On clean renders the same glyph in two
  frames correlates at >= 0.96 (99.9 % of glyphs), glyphs of different classes at <= 0.86,
  so the threshold sits between them: a glyph that changed its look (a jump, an object
  sliding over it, a lighting change) is classified again;
* it has been carried fewer than ``refresh_frames`` frames in a row: every glyph is
  classified again regularly, spread over the frames (not all in one).

Cells are carried separately (:mod:`tactile_sl_decoder.decode.track`, from ``source``, the
match made here): only when this frame's lattice and labels confirm every carried cell is
the window search skipped; otherwise the frame is decoded from its labels in full, and the
M-array's checks (votes, lattice consistency, islands) judge carried labels exactly like
fresh ones.  Positions are matched after the worker's extraction, in the same thread, per
camera; the state is one frame of one camera (:class:`LabelCarry`).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from tactile_sl_common.settings import SettingsTable
from tactile_sl_decoder.contract import LABEL_UNKNOWN
from tactile_sl_decoder.glyphs import Glyphs
from tactile_sl_decoder.jit import helper, kernel
from tactile_sl_decoder.neighbours import nearest_within

CROP = 3   # pixels left out on each side of a patch for the correlation (the glyph's ring)


@dataclass
class CarryParams:
    """When a glyph keeps the label of the glyph at its place in the previous frame."""

    enabled: bool = True
    """A glyph where a glyph was one frame earlier, looking the same, keeps its label instead
    of being classified again (off: every glyph is classified every frame)."""
    radius: float = 0.3
    """Largest distance from the previous glyph's predicted position, in glyph spacings."""
    min_correlation: float = 0.93
    """Smallest correlation of the two glyph patches."""
    min_confidence: float = 0.9
    """Smallest confidence of the label carried."""
    refresh_frames: int = 8
    """Every glyph is classified again after at most this many frames, and every frame
    decoded in full after at most this many."""
    cells: bool = True
    """Cells too: when this frame's lattice and labels confirm the cell of every glyph
    matched to the previous frame, the window search is skipped."""

    def validate(self) -> "CarryParams":
        """Raise ValueError naming the first setting outside :data:`CARRY_SETTINGS`."""
        CARRY_SETTINGS.check(self, "carry.")
        return self


CARRY_SETTINGS = SettingsTable(CarryParams, ranges={
    "radius": (0.05, 0.5), "min_correlation": (0.5, 1.0), "min_confidence": (0.0, 1.0),
    "refresh_frames": (1, 1000)})
"""The decoder node's live ``carry.<field>`` parameters."""


def normalised_patches(patches: np.ndarray) -> np.ndarray:
    """(N, s, s) uint8 -> (N, (s - 2 CROP)^2) float32, zero mean and unit norm per patch.

    :func:`_normalised` (one GIL-free call instead of some ten numpy calls that hold the
    GIL between them: the two images' workers run this at once) where it gives
    :func:`numpy_normalised_patches`'s bits (:func:`_kernels_are_exact`), else that.
    """
    if patches.dtype == np.uint8 and patches.ndim == 3 and \
            min(patches.shape[1:]) > 2 * CROP and _kernels_are_exact():
        return _normalised(np.ascontiguousarray(patches), CROP)
    return numpy_normalised_patches(patches)


def numpy_normalised_patches(patches: np.ndarray) -> np.ndarray:
    """:func:`normalised_patches` in numpy, the kernel's reference.

    The sums are matrix products (a product with ones, a row-wise dot product): a third of
    ``mean`` / ``linalg.norm``'s time per frame, within 1e-7 of them.
    """
    n = len(patches)
    core = patches[:, CROP:patches.shape[1] - CROP, CROP:patches.shape[2] - CROP]
    x = core.reshape(n, -1).astype(np.float32)
    x -= ((x @ np.ones(x.shape[1], np.float32)) / np.float32(x.shape[1]))[:, None]
    norm = np.sqrt(np.einsum("ij,ij->i", x, x))
    x /= np.maximum(norm, np.float32(1e-6))[:, None]
    return x


def correlations(a: np.ndarray, ia: np.ndarray, b: np.ndarray, ib: np.ndarray) -> np.ndarray:
    """(K,) float32 dot products of rows a[ia] and b[ib] (normalised patches: correlations).

    :func:`_row_dots` where it gives numpy's einsum bits (one GIL-free call, no copies of
    the rows), else ``np.einsum`` of the rows.  The indices must be in range (the kernel
    does not check them; the carry's come from matching, they are).
    """
    if a.dtype == b.dtype == np.float32 and a.ndim == b.ndim == 2 and \
            a.shape[1] == b.shape[1] and len(ia) and _kernels_are_exact():
        return _row_dots(np.ascontiguousarray(a), np.ascontiguousarray(ia, np.int64),
                         np.ascontiguousarray(b), np.ascontiguousarray(ib, np.int64))
    return np.einsum("ij,ij->i", a[ia], b[ib])


@functools.cache
def _kernels_are_exact() -> bool:
    """Whether :func:`_normalised` and :func:`_row_dots` give numpy's bits, once per process.

    numpy's einsum sums a row in an order of its own (its build's SIMD; what
    :func:`_einsum_dot` reproduces): checked on a fixed sample of random, flat, bright and
    smooth patches, of the decoder's size and odd ones (tails of the SIMD loop).
    """
    rng = np.random.default_rng(20261203)
    for size, n in ((18, 300), (11, 40), (9, 40), (7, 20)):
        patches = rng.integers(0, 256, (n, size, size), dtype=np.uint8)
        patches[:4] = np.array([0, 77, 255, 254], np.uint8)[:, None, None]
        patches[4:n // 4] = rng.integers(200, 256, (n // 4 - 4, size, size))
        ramp = np.add.outer(np.arange(size), np.arange(size))
        patches[n // 4:n // 2] = np.clip(rng.uniform(0, 20, (n // 2 - n // 4, 1, 1)) * ramp
                                         + rng.uniform(0, 60, (n // 2 - n // 4, 1, 1)), 0, 255)
        want = numpy_normalised_patches(patches)
        got = _normalised(patches, CROP)
        if not np.array_equal(got, want):
            return False
        ia = rng.integers(0, n, 2 * n)
        ib = rng.integers(0, n, 2 * n)
        ib[:n] = ia[:n]                     # the patch itself: 1 up to rounding
        if not np.array_equal(_row_dots(want, ia, want, ib),
                              np.einsum("ij,ij->i", want[ia], want[ib])):
            return False
    return True


@helper
def _einsum_dot(a: np.ndarray, b: np.ndarray) -> np.float32:
    """The dot product of float32 rows a, b as numpy's einsum sums it (x86-64 SSE baseline).

    Four lanes (element k in lane k mod 4), each a chain of unfused multiply-adds over
    blocks of 16 elements taken last quarter first, then the tail 4 at a time (zeros
    past the end), then (l0 + l1) + (l2 + l3), added to a 0 output.
    """
    zero = np.float32(0.0)
    l0 = l1 = l2 = l3 = zero
    count = a.shape[0]
    k = 0
    while count - k >= 16:
        for at in (k + 12, k + 8, k + 4, k):
            l0 = a[at] * b[at] + l0
            l1 = a[at + 1] * b[at + 1] + l1
            l2 = a[at + 2] * b[at + 2] + l2
            l3 = a[at + 3] * b[at + 3] + l3
        k += 16
    while k < count:      # the tail, zero-padded to 4 (0 * 0 leaves a lane, never -0, as it is)
        l0 = a[k] * b[k] + l0
        if k + 1 < count:
            l1 = a[k + 1] * b[k + 1] + l1
        if k + 2 < count:
            l2 = a[k + 2] * b[k + 2] + l2
        if k + 3 < count:
            l3 = a[k + 3] * b[k + 3] + l3
        k += 4
    return zero + ((l0 + l1) + (l2 + l3))


_NORMALISED_SIGNATURE = "float32[:, ::1]({patches}, int64)"


@kernel([_NORMALISED_SIGNATURE.format(patches="uint8[:, :, ::1]"),
         _NORMALISED_SIGNATURE.format(patches="Array(uint8, 3, 'C', readonly=True)")])
def _normalised(patches: np.ndarray, crop: int) -> np.ndarray:
    """:func:`numpy_normalised_patches` per patch, in numpy's float32 operations and order.

    The mean's sum (integers) is exact in any order; the norm's is numpy einsum's
    (:func:`_einsum_dot`).
    """
    n = patches.shape[0]
    rows = patches.shape[1] - 2 * crop
    cols = patches.shape[2] - 2 * crop
    d = rows * cols
    out = np.empty((n, d), np.float32)
    size = np.float32(d)
    floor = np.float32(1e-6)
    for i in range(n):
        x = out[i]
        total = 0
        for r in range(rows):
            line = patches[i, crop + r]
            for c in range(cols):
                v = line[crop + c]
                total += v
                x[r * cols + c] = np.float32(v)
        mean = np.float32(total) / size
        for k in range(d):
            x[k] = x[k] - mean
        scale = max(np.sqrt(_einsum_dot(x, x)), floor)
        for k in range(d):
            x[k] = x[k] / scale
    return out


@kernel("float32[::1](float32[:, ::1], int64[::1], float32[:, ::1], int64[::1])")
def _row_dots(a: np.ndarray, ia: np.ndarray, b: np.ndarray, ib: np.ndarray) -> np.ndarray:
    """(K,) a[ia[k]] . b[ib[k]] as numpy's einsum sums them (:func:`_einsum_dot`)."""
    out = np.empty(len(ia), np.float32)
    for k in range(len(ia)):
        out[k] = _einsum_dot(a[ia[k]], b[ib[k]])
    return out


@dataclass
class _Frame:
    """What one camera's previous frame leaves for the next one."""

    predicted: np.ndarray     # (N, 2) where each glyph is expected next frame, px
    position: np.ndarray      # (N, 2) where it was, px
    label: np.ndarray         # (N,) uint8
    confidence: np.ndarray    # (N,) float32
    carried_for: np.ndarray   # (N,) int: frames the label has been carried (0: classified)
    patches: np.ndarray       # (N, d) normalised_patches
    spacing_px: float


@dataclass
class Carried:
    """One frame's glyphs matched to the previous frame (:meth:`LabelCarry.carry`)."""

    carried: np.ndarray      # (N,) bool: label and confidence come from the previous frame
    label: np.ndarray        # (N,) uint8, LABEL_UNKNOWN where not carried
    confidence: np.ndarray   # (N,) float32, 0 where not carried
    source: np.ndarray       # (N,) int64: the previous frame's glyph at this place, or -1
    position: np.ndarray     # (N, 2) float64 glyph centres, px
    patches: np.ndarray      # (N, d) normalised_patches
    spacing_px: float


class LabelCarry:
    """Per camera: label glyphs from the previous frame where that is safe (see module doc)."""

    def __init__(self, params: CarryParams | None = None) -> None:
        self.params = params if params is not None else CarryParams()
        self._prev: _Frame | None = None
        self.last: Carried | None = None    # the latest frame's match (its ``source``)

    def reset(self) -> None:
        """Forget the previous frame (the next frame is classified in full)."""
        self._prev = None
        self.last = None

    def carry(self, u: np.ndarray, v: np.ndarray, patches: np.ndarray, spacing_px: float
              ) -> Carried:
        """Match this frame's glyphs (centres, (N, s, s) patches) to the previous frame's."""
        p = self.params
        n = len(u)
        pos = np.column_stack([u, v]).astype(np.float64)
        normed = normalised_patches(patches)
        out = Carried(np.zeros(n, bool), np.full(n, LABEL_UNKNOWN, np.uint8),
                      np.zeros(n, np.float32), np.full(n, -1, np.int64), pos, normed,
                      float(spacing_px))
        prev = self._prev
        self.last = out
        if out.spacing_px <= 0 and prev is not None:
            out.spacing_px = prev.spacing_px
        if not p.enabled or prev is None or n == 0 or len(prev.label) == 0 or \
                out.spacing_px <= 0:
            return out
        dist, j = nearest_within(np.ascontiguousarray(pos[:, 0]), np.ascontiguousarray(pos[:, 1]),
                                 np.ascontiguousarray(prev.predicted[:, 0]),
                                 np.ascontiguousarray(prev.predicted[:, 1]),
                                 p.radius * out.spacing_px)
        cand = np.flatnonzero(np.isfinite(dist))
        j = j[cand]
        # one glyph per previous glyph (two glyphs this close: one of them is no glyph)
        unique = np.bincount(j, minlength=len(prev.label))[j] == 1
        cand, j = cand[unique], j[unique]
        if len(cand) == 0:
            return out
        out.source[cand] = j
        keep = ((prev.label[j] != LABEL_UNKNOWN) & (prev.confidence[j] >= p.min_confidence)
                & (prev.carried_for[j] + 1 < p.refresh_frames))
        cand, j = cand[keep], j[keep]
        corr = correlations(normed, cand, prev.patches, j)
        keep = corr >= p.min_correlation
        cand, j = cand[keep], j[keep]
        out.carried[cand] = True
        out.label[cand] = prev.label[j]
        out.confidence[cand] = prev.confidence[j]
        return out

    def remember(self, frame: Carried, label: np.ndarray, confidence: np.ndarray) -> None:
        """Keep this frame, with its final labels and confidences, for the next one."""
        prev = self._prev
        n = len(label)
        carried_for = np.zeros(n, np.int64)
        velocity = np.zeros((n, 2))
        if prev is not None:
            has = frame.source >= 0
            j = frame.source[has]
            carried_for[has] = prev.carried_for[j] + 1
            velocity[has] = frame.position[has] - prev.position[j]
        # Classified glyphs start again at 0; glyphs new at their place at staggered counts,
        # so that after a full classification the refresh is spread over the next frames.
        carried_for[~frame.carried] = 0
        new = np.flatnonzero(frame.source < 0)
        carried_for[new] = new % self.params.refresh_frames
        self._prev = _Frame(frame.position + velocity, frame.position,
                            np.asarray(label, np.uint8).copy(),
                            np.asarray(confidence, np.float32).copy(), carried_for,
                            frame.patches, frame.spacing_px)


def label_glyphs(images: Sequence[Glyphs], carries: Sequence[LabelCarry | None],
                 predict: Callable[[np.ndarray], tuple[np.ndarray, Any]]) -> int:
    """Label the glyphs of one or more images (in place), one classifier batch.

    With a :class:`LabelCarry` per image, glyphs that keep the previous frame's label are
    not classified; ``predict`` (patches -> labels, confidences) sees the others only, and
    is not called when there are none.  Returns the number of glyphs labelled from the
    previous frame.
    """
    work = [(g, c) for g, c in zip(images, carries) if len(g) and g.patches is not None]
    for g, c in zip(images, carries):
        if c is not None and not (len(g) and g.patches is not None):
            c.reset()
    if not work:
        return 0
    patches = [np.asarray(g.patches) for g, _ in work]
    frames = [c.carry(g.u, g.v, p, g.spacing_px) if c is not None else None
              for (g, c), p in zip(work, patches)]
    todo = [np.flatnonzero(~f.carried) if f is not None else slice(None) for f in frames]
    batch = [p[t] for p, t in zip(patches, todo)]
    sizes = [len(b) for b in batch]
    label, conf = (predict(np.concatenate(batch)) if sum(sizes)
                   else (np.zeros(0, np.uint8), np.zeros(0, np.float32)))
    start = carried = 0
    for (g, c), f, t, k in zip(work, frames, todo, sizes):
        if f is None:
            g.label = np.asarray(label[start:start + k], np.uint8)
            g.confidence = np.asarray(conf[start:start + k], np.float32)
        else:
            g.label, g.confidence = f.label.copy(), f.confidence.copy()
            g.label[t] = label[start:start + k]
            g.confidence[t] = conf[start:start + k]
            assert c is not None     # f is None exactly where c is
            c.remember(f, g.label, g.confidence)
            carried += int(f.carried.sum())
        start += k
    return carried
