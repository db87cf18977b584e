"""Glyph classification: load the shipped CNN weights and label patches fast on one core.

Two architectures (:mod:`tactile_sl_decoder.classify.model`): the default ``tiny9-18``
(:class:`~.model.GlyphNetTiny`, ``data/classifier.pt``: a 2x2 mean-pool, one 3x3 convolution
and two fully connected layers, about a third of LeNet's time per patch at LeNet's
held-out accuracy) and LeNet-5 ``lenet5-18`` (``data/classifier_lenet5.pt``, selectable with
the ``classifier_weights`` parameter or ``--weights``).  Training uses torch; inference
computes the same functions without torch, as a handful of large numpy matrix products
(OpenBLAS calls that release the GIL, so the two images' workers overlap), because torch's
default CPU path costs 7-9 ms for 1,000 patches of a net this small (framework overhead per
layer, tiny convolutions), and importing torch alone costs a process ~3.5 s of CPU at start.
For LeNet (:class:`FastLeNet`):

* conv1: output row r depends on input rows r..r+4. The 14 output columns are split into
  blocks 0..7 and 8..13 (pooling pairs never straddle them), which read input columns 0..11
  and 8..17; laid out block by block, the 5 input rows of an output row are 60 (or 50)
  consecutive values, and one (N, 60) x (60, 48) plus one (N, 50) x (50, 36) product with
  banded "Toeplitz" matrices holding the 5x5 kernels yield all 14 columns x 6 channels of
  that row, ordered (pooled column, parity, channel) so that 2x2 max-pooling is two
  elementwise maxima; it runs one pooled row at a time in buffers that stay in cache;
* conv2 likewise, summing five (N, 42) x (42, 48) products per output row;
* the per-patch standardisation, bias and ReLU are applied after pooling (all commute
  with max).

Each prediction carries the softmax probability of its label; below the confidence
threshold (default :data:`DEFAULT_THRESHOLD`) the label is 255 (unknown), so the decoder
can correct the glyph from its neighbours instead of trusting a guess.
"""
from __future__ import annotations

import pickle
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from tactile_sl_decoder.classify.weights_file import WeightsFileError, read_torch_zip
from tactile_sl_decoder.contract import LABEL_UNKNOWN, PATCH_SIZE
from tactile_sl_decoder.jit import fma32, helper, kernel

FORMAT = "tactile_sl_classifier"
FORMAT_VERSION = 1
LENET_ARCH = "lenet5-18"
"""Architecture tag of :class:`~.model.GlyphNet` (LeNet-5) stored with the weights."""
TINY_ARCH = "tiny9-18"
"""Architecture tag of :class:`~.model.GlyphNetTiny` stored with the weights."""
ARCH = TINY_ARCH
"""The architecture of the shipped default weights (data/classifier.pt)."""
ARCH_DESCRIPTIONS = {
    LENET_ARCH: "LeNet-5 style, 18x18 grey patch (standardised per patch) -> conv 6@5x5 -> "
                "max-pool -> conv 16@5x5 -> max-pool (ceil) -> FC 32 -> FC 64",
    TINY_ARCH: "right-sized CNN, 18x18 grey patch (standardised per patch) -> 2x2 mean-pool "
               "-> conv 16@3x3 -> max-pool (ceil) -> FC 32",
}
"""What each architecture is, for model cards and help texts."""
DEFAULT_THRESHOLD = 0.9
"""Minimum softmax probability for a label to be reported; below it the label is 255."""

# Parameter shapes per architecture: ints are fixed, "K" the classes, "C" / "H" the tiny
# net's channels and hidden units (read from the weights, the same everywhere they occur).
_SHAPES: dict[str, dict[str, tuple[int | str, ...]]] = {
    LENET_ARCH: {
        "conv1.weight": (6, 1, 5, 5), "conv1.bias": (6,),
        "conv2.weight": (16, 6, 5, 5), "conv2.bias": (16,),
        "fc1.weight": (32, 64), "fc1.bias": (32,),
        "fc2.weight": (64, 32), "fc2.bias": (64,),
        "out.weight": ("K", 64), "out.bias": ("K",)},
    TINY_ARCH: {
        "conv1.weight": ("C", 1, 3, 3), "conv1.bias": ("C",),
        "fc1.weight": ("H", "C16"), "fc1.bias": ("H",),
        "out.weight": ("K", "H"), "out.bias": ("K",)},
}


class ClassifierError(ValueError):
    """A weights file that is missing, of another format/version/architecture, or misshapen."""


def default_weights_path() -> Path:
    """The weights the package ships (trained by ``tactile-sl train``)."""
    return Path(__file__).resolve().parent.parent / "data" / "classifier.pt"


def check_state(state: dict[str, Any], arch: str = LENET_ARCH) -> int:
    """Validate a state dict's names and shapes for ``arch``; returns the number of classes."""
    shapes = _SHAPES.get(arch)
    if shapes is None:
        raise ClassifierError(f"unknown architecture {arch!r} (known: {', '.join(_SHAPES)})")
    missing = [k for k in shapes if k not in state]
    if missing:
        raise ClassifierError(f"weights lack {', '.join(missing)} (not a {arch} state dict)")
    dims = {"K": int(np.asarray(state["out.bias"]).shape[0])}
    if arch == TINY_ARCH:
        dims["C"] = int(np.asarray(state["conv1.bias"]).shape[0])
        dims["H"] = int(np.asarray(state["fc1.bias"]).shape[0])
        dims["C16"] = 16 * dims["C"]
    for key, shape in shapes.items():
        want = tuple(dims[d] if isinstance(d, str) else d for d in shape)
        got = tuple(np.asarray(state[key]).shape)
        if got != want:
            raise ClassifierError(f"weight {key} has shape {got}, expected {want} for {arch} "
                                  f"with {dims['K']} classes")
    classes = dims["K"]
    if classes < 2 or classes > 254:
        raise ClassifierError(f"{classes} classes is not a usable alphabet")
    return classes


@dataclass
class FastLeNet:
    """The numpy form of :class:`~tactile_sl_decoder.classify.model.GlyphNet` (same outputs)."""

    t1a: np.ndarray  # (60, 48) banded conv1 matrix: 5 rows x input cols 0..11 -> cols 0..7
    t1b: np.ndarray  # (50, 36) banded conv1 matrix: 5 rows x input cols 8..17 -> cols 8..13
    s1: np.ndarray  # (42,) sum of each conv1 kernel, tiled over 7 pooled columns
    b1: np.ndarray  # (42,) conv1 bias, tiled likewise
    t2: np.ndarray  # (210, 48) banded conv2 matrix: 5 rows x (7 cols, 6 ch) -> (3 cols, 16 ch)
    b2: np.ndarray  # (64,) conv2 bias tiled over the 2x2 pooled positions
    w3: np.ndarray  # (64, 32) fc1, rows reordered to (row, col, channel)
    b3: np.ndarray
    w4: np.ndarray  # (32, 64)
    b4: np.ndarray
    w5: np.ndarray  # (64, classes)
    b5: np.ndarray

    # conv1 output columns are split into two blocks that pooling never straddles, 0..7 and
    # 8..13, and ordered (pooled column, column parity, channel) inside each block
    _BLOCKS = ((0, 8, 12), (8, 14, 10))  # (first output col, end output col, input cols)

    @staticmethod
    def from_state(state: dict[str, Any]) -> FastLeNet:
        """Rearrange torch-layout weights into the banded matrices used by :meth:`logits`."""
        check_state(state, LENET_ARCH)
        s = {k: np.asarray(v, dtype=np.float32) for k, v in state.items()}
        w1, w2 = s["conv1.weight"], s["conv2.weight"]
        t1 = []
        for first, end, width in FastLeNet._BLOCKS:
            # (dy, input col, pooled col, parity, channel)
            t = np.zeros((5, width, (end - first) // 2, 2, 6), np.float32)
            for c in range(first, end):
                for dx in range(5):
                    t[:, c - first + dx, (c - first) // 2, (c - first) % 2, :] = w1[:, 0, :, dx].T
            t1.append(np.ascontiguousarray(t.reshape(5 * width, 6 * (end - first))))
        t2 = np.zeros((5, 7, 6, 3, 16), np.float32)  # (dy, in col, in ch, out col, out ch)
        for c in range(3):
            for dx in range(5):
                t2[:, c + dx, :, c, :] = w2[:, :, :, dx].transpose(2, 1, 0)
        # torch flattens (channel, row, col); our pooled features are (row, col, channel)
        w3 = s["fc1.weight"].reshape(32, 16, 2, 2).transpose(2, 3, 1, 0).reshape(64, 32)
        return FastLeNet(
            t1[0], t1[1], np.tile(w1.sum(axis=(1, 2, 3)), 7),
            np.tile(s["conv1.bias"], 7), t2.reshape(210, 48), np.tile(s["conv2.bias"], 4),
            np.ascontiguousarray(w3), s["fc1.bias"], np.ascontiguousarray(s["fc2.weight"].T),
            s["fc2.bias"], np.ascontiguousarray(s["out.weight"].T), s["out.bias"])

    def logits(self, patches: np.ndarray) -> np.ndarray:
        """(N, classes) float32 logits of (N, 18, 18) uint8 patches."""
        n = patches.shape[0]
        x = np.ascontiguousarray(patches).reshape(n, PATCH_SIZE * PATCH_SIZE)
        x = x.astype(np.float32)
        # per-patch standardisation (x - m) / s is applied after conv1 and pooling: it is a
        # per-patch, per-channel affine map with positive scale, so it commutes with max
        mean = x.mean(axis=1)
        var = np.einsum("ij,ij->i", x, x) / np.float32(x.shape[1]) - mean * mean
        inv = np.float32(1.0) / (np.sqrt(np.maximum(var, np.float32(0.0))) + np.float32(1.0))
        # the two column blocks' inputs, laid out so that the 5 input rows of one output row
        # are consecutive values
        cube = x.reshape(n, PATCH_SIZE, PATCH_SIZE)
        fa = np.ascontiguousarray(cube[:, :, 0:12]).reshape(n, PATCH_SIZE * 12)
        fb = np.ascontiguousarray(cube[:, :, 8:18]).reshape(n, PATCH_SIZE * 10)
        # one pooled row at a time, in two (N, 84) buffers that stay in cache: the even and
        # the odd conv1 row, their maximum, then the maximum of column pairs
        even = np.empty((n, 84), np.float32)
        odd = np.empty((n, 84), np.float32)
        pairs = even.reshape(n, 7, 2, 6)
        p1 = np.empty((7, n, 42), np.float32)  # (pooled row, patch, (pooled col, channel))
        ta, tb = self.t1a, self.t1b
        for k in range(7):  # 28 matrix products and 14 maxima, not a loop over glyphs
            r = 2 * k
            np.matmul(fa[:, r * 12:r * 12 + 60], ta, out=even[:, 0:48])
            np.matmul(fb[:, r * 10:r * 10 + 50], tb, out=even[:, 48:84])
            np.matmul(fa[:, r * 12 + 12:r * 12 + 72], ta, out=odd[:, 0:48])
            np.matmul(fb[:, r * 10 + 10:r * 10 + 60], tb, out=odd[:, 48:84])
            np.maximum(even, odd, out=even)
            np.maximum(pairs[:, :, 0], pairs[:, :, 1], out=p1[k].reshape(n, 7, 6))
        # relu((p1 - mean * s1) * inv + b1) = relu(p1 * inv + (b1 - mean * inv * s1))
        p1 *= inv[:, None]
        p1 += self.b1 - (mean * inv)[:, None] * self.s1
        np.maximum(p1, np.float32(0.0), out=p1)
        t2 = self.t2.reshape(5, 42, 48)
        z = np.empty((3, n, 48), np.float32)
        term = np.empty((n, 48), np.float32)
        for q in range(3):  # conv2 output row q = sum over its 5 kernel rows
            np.matmul(p1[q], t2[0], out=z[q])
            for dy in range(1, 5):
                np.matmul(p1[q + dy], t2[dy], out=term)
                z[q] += term
        r0 = np.maximum(z[0], z[1])  # ceil-mode pooling of 3 rows: {0, 1}, {2}
        r1 = z[2]
        feats = np.concatenate((np.maximum(r0[:, 0:16], r0[:, 16:32]), r0[:, 32:48],
                                np.maximum(r1[:, 0:16], r1[:, 16:32]), r1[:, 32:48]), axis=1)
        feats += self.b2
        np.maximum(feats, np.float32(0.0), out=feats)
        h = feats @ self.w3
        h += self.b3
        np.maximum(h, np.float32(0.0), out=h)
        h2 = h @ self.w4
        h2 += self.b4
        np.maximum(h2, np.float32(0.0), out=h2)
        out = h2 @ self.w5
        out += self.b5
        return out


@dataclass
class FastTiny:
    """The numpy form of :class:`~tactile_sl_decoder.classify.model.GlyphNetTiny`.

    The 2x2 average pool is OpenCV's area resize of the patches stacked into one tall
    image; the 3x3 convolution of the 9x9 pooled patch is one matrix product of each output
    row's three input rows (27 consecutive values) with a banded (27, 8 x channels) matrix.
    Output rows are laid out even ones first (0, 2, 4, 6) then odd ones (1, 3, 5, 6) and the
    columns likewise, so the ceil-mode 2x2 max-pool is two maxima of contiguous halves; the
    standardisation, bias and ReLU come after it (they commute with max, as in
    :class:`FastLeNet`).

    That is some 25 numpy calls on small arrays, each holding the GIL between them, so the
    two images' workers stall each other: :meth:`_logits` runs everything up to the hidden
    layer as one kernel (:func:`_tiny_hidden`, GIL released), and only the last product
    stays numpy's.  The kernel sums each product as a chain of fused multiply-adds from 0
    in ascending k, on every CPU: for the shipped network's shapes OpenBLAS's AVX-512 sgemm
    sums in that order, so there it gives the numpy code's bits; on AVX2 CPUs (and for
    some other shapes) OpenBLAS sums in another order and the two differ in the last bits
    (labels and every bag's outputs unchanged, docs/extraction.md).
    :meth:`_numpy_logits` runs for one patch (numpy's gemv, as always), float patches and
    a band of another layout.
    """

    band: np.ndarray   # (27, 8 * C): 3 pooled rows x 9 cols -> cols (0,2,4,6,1,3,5,6) x C
    s1: np.ndarray     # (C,) sum of each kernel (the standardisation's mean term)
    b1: np.ndarray     # (C,)
    w2: np.ndarray     # (16 C, hidden) fc1, rows reordered to (row, col, channel)
    b2: np.ndarray
    w3: np.ndarray     # (hidden, classes)
    b3: np.ndarray

    _ORDER = (0, 2, 4, 6, 1, 3, 5, 6)   # conv output rows / columns: pooling partners apart

    @staticmethod
    def from_state(state: dict[str, Any]) -> FastTiny:
        """Rearrange torch-layout weights into the banded matrix used by :meth:`logits`."""
        check_state(state, TINY_ARCH)
        s = {k: np.asarray(v, dtype=np.float32) for k, v in state.items()}
        w1 = s["conv1.weight"]
        channels = w1.shape[0]
        band = np.zeros((3, 9, 8, channels), np.float32)   # (dy, input col, slot, channel)
        for slot, c in enumerate(FastTiny._ORDER):
            for dx in range(3):
                band[:, c + dx, slot, :] = 0.25 * w1[:, 0, :, dx].T   # 0.25: the mean pool
        hidden = s["fc1.weight"].shape[0]
        w2 = s["fc1.weight"].reshape(hidden, channels, 4, 4).transpose(2, 3, 1, 0)
        return FastTiny(band.reshape(27, 8 * channels), w1.sum(axis=(1, 2, 3)),
                        s["conv1.bias"], np.ascontiguousarray(w2.reshape(16 * channels, hidden)),
                        s["fc1.bias"], np.ascontiguousarray(s["out.weight"].T), s["out.bias"])

    _BLOCK = 512   # patches per pass: the convolution's output (4 KB a patch) stays in cache

    def logits(self, patches: np.ndarray) -> np.ndarray:
        """(N, classes) float32 logits of (N, 18, 18) uint8 patches."""
        n = patches.shape[0]
        if n == 0:
            return np.zeros((0, self.b3.shape[0]), np.float32)
        if n <= self._BLOCK:
            return self._logits(patches)
        out = np.empty((n, self.b3.shape[0]), np.float32)
        for start in range(0, n, self._BLOCK):
            out[start:start + self._BLOCK] = self._logits(patches[start:start + self._BLOCK])
        return out

    def _logits(self, patches: np.ndarray) -> np.ndarray:
        """:meth:`_numpy_logits`'s network, through :func:`_tiny_hidden` for uint8 batches."""
        taps = self._taps()
        if len(patches) < 2 or patches.dtype != np.uint8 or taps is None:
            return self._numpy_logits(patches)
        return self._kernel_logits(patches, taps)

    def _kernel_logits(self, patches: np.ndarray, taps: np.ndarray) -> np.ndarray:
        """The kernel's hidden layer, then numpy's last product (one GIL-free call each)."""
        x = np.ascontiguousarray(patches).reshape(len(patches), PATCH_SIZE * PATCH_SIZE)
        h = _tiny_hidden(x, taps, self.s1, self.b1, self.w2, self.b2)
        out = h @ self.w3
        out += self.b3
        return out

    def _taps(self) -> np.ndarray | None:
        """The (3, 3, C) convolution taps :func:`_tiny_hidden` reads, or None.

        None where the band is not the layout :meth:`from_state` makes (the kernel reads
        only the 3x3 taps) or the arrays are not of the kernel's types.  Built once per band
        (the arrays are not modified after loading).
        """
        cached = self.__dict__.get("_taps_cache")
        if cached is not None and cached[0] is self.band:
            return cached[1]
        found = None
        arrays = (self.band, self.s1, self.b1, self.w2, self.b2)
        channels = self.s1.shape[0]
        if all(a.dtype == np.float32 and a.flags.c_contiguous for a in arrays) \
                and self.band.shape == (27, 8 * channels) and self.b1.shape == (channels,) \
                and self.w2.shape[0] == 16 * channels and self.b2.shape == (self.w2.shape[1],):
            taps = np.ascontiguousarray(self.band.reshape(3, 9, 8 * channels)[:, 0:3, 0:channels])
            band = np.zeros((3, 9, 8, channels), np.float32)
            for slot, c in enumerate(self._ORDER):
                band[:, c:c + 3, slot, :] = taps
            if np.array_equal(band.reshape(27, 8 * channels), self.band) and \
                    not np.signbit(self.band[self.band == 0]).any():
                found = taps
        self.__dict__["_taps_cache"] = (self.band, found)
        return found

    def _numpy_logits(self, patches: np.ndarray) -> np.ndarray:
        """The network through numpy, OpenBLAS and OpenCV calls.

        Its products are summed as OpenBLAS does on the CPU at hand: on AVX-512, the
        kernel's bits; on AVX2, within float32 rounding of them (docs/extraction.md).
        """
        n = patches.shape[0]
        channels = self.s1.shape[0]
        x = np.ascontiguousarray(patches).reshape(n, PATCH_SIZE * PATCH_SIZE).astype(np.float32)
        size = np.float32(x.shape[1])
        mean = (x @ np.ones(x.shape[1], np.float32)) / size
        var = np.einsum("ij,ij->i", x, x) / size - mean * mean
        inv = np.float32(1.0) / (np.sqrt(np.maximum(var, np.float32(0.0))) + np.float32(1.0))
        pooled = cv2.resize(x.reshape(n * PATCH_SIZE, PATCH_SIZE), (9, 9 * n),
                            interpolation=cv2.INTER_AREA).reshape(n, 81) * np.float32(4.0)
        # each output row's 3 input rows: rows 0, 2, 4, 6 then 1, 3, 5, 6
        rows = np.empty((n, 8, 27), np.float32)
        step = pooled.strides[1]
        view = np.lib.stride_tricks.as_strided
        rows[:, 0:4] = view(pooled, (n, 4, 27), (pooled.strides[0], 18 * step, step))
        rows[:, 4:7] = view(pooled[:, 9:], (n, 3, 27), (pooled.strides[0], 18 * step, step))
        rows[:, 7] = pooled[:, 54:81]
        conv = (rows.reshape(n * 8, 27) @ self.band).reshape(n, 8, 8 * channels)
        by_row = np.maximum(conv[:, 0:4], conv[:, 4:8])                   # (n, 4, 8 C)
        feats = np.maximum(by_row[:, :, :4 * channels], by_row[:, :, 4 * channels:])
        feats = feats.reshape(n, 16, channels)                           # (row, col, ch)
        feats *= inv[:, None, None]
        feats += self.b1 - (mean * inv)[:, None, None] * self.s1
        np.maximum(feats, np.float32(0.0), out=feats)
        h = feats.reshape(n, 16 * channels) @ self.w2
        h += self.b2
        np.maximum(h, np.float32(0.0), out=h)
        out = h @ self.w3
        out += self.b3
        return out


_HIDDEN_SIGNATURE = ("float32[:, ::1]({x}, float32[:, :, ::1], float32[::1], float32[::1], "
                     "float32[:, ::1], float32[::1])")

_KERNEL_BLOCK = 128
"""Patches :func:`_tiny_hidden` takes at once: its loops run across them (long enough for
vector instructions) while the block's intermediate arrays stay in cache."""

@helper
def _standardise_pool(x: np.ndarray, start: int, m: int, inv: np.ndarray, shift: np.ndarray,
                      pooled: np.ndarray) -> None:
    """Per patch x[start + b]: 1 / (std + 1), mean / (std + 1), 4 x the 2x2 mean pool."""
    size = np.float32(x.shape[1])
    zero = np.float32(0.0)
    for b in range(m):
        i = start + b
        total = np.int64(0)
        squares = np.int64(0)
        for j in range(x.shape[1]):
            v = np.int64(x[i, j])
            total += v
            squares += v * v
        mean = np.float32(total) / size
        var = np.float32(squares) / size - mean * mean
        inv[b] = np.float32(1.0) / (np.sqrt(max(var, zero)) + np.float32(1.0))
        shift[b] = mean * inv[b]
        for r in range(9):
            for c in range(9):
                at = 36 * r + 2 * c
                pooled[9 * r + c, b] = np.float32(
                    np.int64(x[i, at]) + np.int64(x[i, at + 1]) + np.int64(x[i, at + 18])
                    + np.int64(x[i, at + 19]))


@helper
def _conv_pool(pooled: np.ndarray, taps: np.ndarray, s1: np.ndarray, b1: np.ndarray,
               inv: np.ndarray, shift: np.ndarray, m: int, conv: np.ndarray,
               feats: np.ndarray) -> None:
    """feats[(row, col, channel), patch]: conv, max-pool, standardisation, bias, ReLU.

    The convolution as OpenBLAS sums a row of the band product: fused multiply-adds from 0,
    k ascending (row dy, then column dx); the band's zeros are left out (a multiply-add of
    zero leaves the sum, never -0, as it is).  The ceil-mode 2x2 max-pool takes rows, then
    columns, as numpy does.
    """
    zero = np.float32(0.0)
    channels = s1.shape[0]
    for ch in range(channels):
        t0, t1, t2 = taps[0, 0, ch], taps[0, 1, ch], taps[0, 2, ch]
        t3, t4, t5 = taps[1, 0, ch], taps[1, 1, ch], taps[1, 2, ch]
        t6, t7, t8 = taps[2, 0, ch], taps[2, 1, ch], taps[2, 2, ch]
        for q in range(49):
            p = 9 * (q // 7) + q % 7
            for b in range(m):
                a = fma32(pooled[p, b], t0, zero)
                a = fma32(pooled[p + 1, b], t1, a)
                a = fma32(pooled[p + 2, b], t2, a)
                a = fma32(pooled[p + 9, b], t3, a)
                a = fma32(pooled[p + 10, b], t4, a)
                a = fma32(pooled[p + 11, b], t5, a)
                a = fma32(pooled[p + 18, b], t6, a)
                a = fma32(pooled[p + 19, b], t7, a)
                conv[q, b] = fma32(pooled[p + 20, b], t8, a)
        bias = b1[ch]
        scale = s1[ch]
        for pr in range(4):
            r0, r1 = 14 * pr, 7 * min(2 * pr + 1, 6)
            for pc in range(4):
                c0, c1 = 2 * pc, min(2 * pc + 1, 6)
                row = (4 * pr + pc) * channels + ch
                for b in range(m):
                    left = max(conv[r0 + c0, b], conv[r1 + c0, b])
                    right = max(conv[r0 + c1, b], conv[r1 + c1, b])
                    v = max(left, right) * inv[b] + (bias - shift[b] * scale)
                    feats[row, b] = v if v > zero else zero


@helper
def _dense(feats: np.ndarray, w2: np.ndarray, b2: np.ndarray, m: int, acc: np.ndarray,
           out: np.ndarray) -> None:
    """out[b] = relu(feats[:, b] @ w2 + b2) as OpenBLAS sums it (k ascending, from 0)."""
    zero = np.float32(0.0)
    for j in range(w2.shape[1]):
        for b in range(m):
            acc[j, b] = zero
        for k in range(w2.shape[0]):
            weight = w2[k, j]
            for b in range(m):
                acc[j, b] = fma32(feats[k, b], weight, acc[j, b])
        bias = b2[j]
        for b in range(m):
            v = acc[j, b] + bias
            out[b, j] = v if v > zero else zero


@kernel([_HIDDEN_SIGNATURE.format(x="uint8[:, ::1]"),
         _HIDDEN_SIGNATURE.format(x="Array(uint8, 2, 'C', readonly=True)")])
def _tiny_hidden(x: np.ndarray, taps: np.ndarray, s1: np.ndarray, b1: np.ndarray,
                 w2: np.ndarray, b2: np.ndarray) -> np.ndarray:
    """(N, hidden) ReLU'd hidden layer of :class:`FastTiny` for (N, 324) uint8 patches.

    :meth:`FastTiny._numpy_logits`'s arithmetic, in blocks of :data:`_KERNEL_BLOCK`
    patches (the innermost loops run across a block's patches, so they become vector
    instructions).  The integer sums (mean, 2x2 area pool) are exact in any order; the sum
    of squares is exact and rounded once to float32 (as numpy einsum's four lanes of at most
    81 squares and their total round); each matrix product is a sequence of fused
    multiply-adds from 0, k ascending (OpenBLAS's AVX-512 sgemm order), the same bits on
    every CPU.  ``taps`` (3, 3, C) is the band's 3x3 kernels (0.25 x conv1).
    """
    n = x.shape[0]
    channels = s1.shape[0]
    hidden = w2.shape[1]
    out = np.empty((n, hidden), np.float32)
    if n == 0:
        return out
    block = min(n, _KERNEL_BLOCK)
    pooled = np.empty((81, block), np.float32)
    inv = np.empty(block, np.float32)
    shift = np.empty(block, np.float32)
    conv = np.empty((49, block), np.float32)
    feats = np.empty((16 * channels, block), np.float32)
    acc = np.empty((hidden, block), np.float32)
    for start in range(0, n, block):
        m = min(block, n - start)
        _standardise_pool(x, start, m, inv, shift, pooled)
        _conv_pool(pooled, taps, s1, b1, inv, shift, m, conv, feats)
        _dense(feats, w2, b2, m, acc, out[start:start + m])
    return out


@dataclass
class Classifier:
    """Labels glyph patches with a symbol value and a confidence (softmax probability)."""

    net: FastLeNet | FastTiny
    classes: int
    threshold: float = DEFAULT_THRESHOLD
    primitives: list[str] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)

    @staticmethod
    def load(path: str | Path | None = None, threshold: float | None = None) -> Classifier:
        """Load weights written by ``tactile-sl train`` (default: the shipped ones).

        Read without torch (:mod:`.weights_file`): plain tensors only, like
        ``torch.load(weights_only=True)``.  A file that reader does not know (another torch
        version's layout) goes to ``torch.load(weights_only=True)`` when torch is installed.
        """
        path = Path(path) if path is not None else default_weights_path()
        if not path.is_file():
            raise ClassifierError(f"classifier weights {path} not found "
                                  f"(run `tactile-sl train` to create them)")
        try:
            blob = read_torch_zip(path)
        except WeightsFileError as exc:
            blob = _torch_load(path, exc)
        return Classifier.from_blob(blob, threshold, source=str(path))

    @staticmethod
    def from_blob(blob: Any, threshold: float | None = None,
                  source: str = "<memory>") -> Classifier:
        """Build from the dict that ``tactile-sl train`` saves (format, version, weights)."""
        if not isinstance(blob, dict) or blob.get("format") != FORMAT:
            raise ClassifierError(f"{source}: not a {FORMAT} file")
        if blob.get("version") != FORMAT_VERSION:
            raise ClassifierError(f"{source}: format version {blob.get('version')!r}, this "
                                  f"build reads version {FORMAT_VERSION}; retrain or upgrade")
        arch = blob.get("arch")
        if arch not in _NETS:
            raise ClassifierError(f"{source}: architecture {arch!r}, expected one of "
                                  f"{', '.join(repr(a) for a in _NETS)}")
        state = {k: _to_numpy(v) for k, v in dict(blob.get("state_dict", {})).items()}
        try:
            net = _NETS[arch].from_state(state)
        except ClassifierError as exc:
            raise ClassifierError(f"{source}: {exc}") from None
        classes = int(state["out.bias"].shape[0])
        th = float(blob.get("threshold", DEFAULT_THRESHOLD) if threshold is None else threshold)
        meta = {k: v for k, v in blob.items() if k not in ("state_dict",)}
        return Classifier(net, classes, th, list(blob.get("primitives", [])), meta)

    def probabilities(self, patches: np.ndarray) -> np.ndarray:
        """(N, classes) float32 softmax probabilities of (N, 18, 18) uint8 patches."""
        patches = _check_patches(patches)
        if len(patches) == 0:
            return np.zeros((0, self.classes), np.float32)
        z = self.net.logits(patches)
        z -= z.max(axis=1, keepdims=True)
        np.exp(z, out=z)
        z /= z.sum(axis=1, keepdims=True)
        return z

    def predict(self, patches: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Labels (uint8, 255 below the threshold) and confidences (float32) of patches."""
        prob = self.probabilities(patches)
        if prob.shape[0] == 0:
            return np.zeros(0, np.uint8), np.zeros(0, np.float32)
        label = prob.argmax(axis=1)
        conf = prob[np.arange(len(label)), label]
        label = label.astype(np.uint8)
        label[conf < self.threshold] = LABEL_UNKNOWN
        return label, conf


_NETS: dict[str, type[FastLeNet] | type[FastTiny]] = {LENET_ARCH: FastLeNet,
                                                       TINY_ARCH: FastTiny}


def _torch_load(path: Path, reason: WeightsFileError) -> Any:
    """``torch.load(weights_only=True)`` of a file the torch-free reader refused.

    torch's own messages are not passed on whole: for a file holding anything but plain
    tensors they advise loading it again with the restriction off, which runs whatever code
    the file carries, advice a user must not follow for a file of unknown origin.
    """
    try:  # torch (1-2 s to import) only for this: the nodes classify without it
        import torch
    except ImportError:
        raise ClassifierError(f"{path}: not a loadable weights file ({reason})") from None
    try:
        with warnings.catch_warnings():     # torch warns about pickle protocols first
            warnings.simplefilter("ignore")
            return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError:
        raise ClassifierError(
            f"{path}: not a loadable weights file ({reason}; torch's tensor-only loader "
            f"refused it too: it is not plain tensors). Use weights written by `tactile-sl "
            f"train`: a file of unknown origin loaded without that restriction could run "
            f"code from it") from None
    except Exception as exc:  # torch raises several types for corrupt / foreign files
        raise ClassifierError(f"{path}: not a loadable weights file ({reason}; torch.load: "
                              f"{_first_sentence(exc)})") from None


def _first_sentence(exc: Exception) -> str:
    """The first sentence of an exception's text (torch appends paragraphs of advice)."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    end = text.find(". ")
    return text if end < 0 else text[:end + 1]


def _to_numpy(value: Any) -> np.ndarray:
    if hasattr(value, "detach"):
        return value.detach().cpu().numpy()
    return np.asarray(value)


def _check_patches(patches: np.ndarray) -> np.ndarray:
    patches = np.asarray(patches)
    if patches.ndim != 3 or patches.shape[1:] != (PATCH_SIZE, PATCH_SIZE):
        raise ValueError(f"patches must be (N, {PATCH_SIZE}, {PATCH_SIZE}), got {patches.shape}")
    if patches.dtype != np.uint8:
        patches = np.clip(patches, 0, 255).astype(np.uint8)
    return patches
