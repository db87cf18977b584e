"""One image's glyphs as flat arrays: the record the pipeline, the nodes and the tools share.

:class:`Glyphs` is what a SymbolArray carries, without ROS; :mod:`.symbol_array` converts it
to and from the message.  Unknown labels and cells hold the sentinels of :mod:`.contract`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from tactile_sl_decoder.contract import CELL_UNKNOWN, LABEL_UNKNOWN, PATCH_SIZE
from tactile_sl_decoder.extract.extraction import Detections


class PipelineInputError(ValueError):
    """A stereo frame the pipeline cannot process (the message says why)."""


def _not_carried() -> np.ndarray:
    """An empty array: the field is not carried and takes its default (as in SymbolArray)."""
    return np.zeros(0, np.float32)


@dataclass
class Glyphs:
    """Glyphs of one image as flat arrays (the SymbolArray fields, without ROS).

    Coordinates are raw (distorted) pixels, OpenCV convention.  ``label``, ``confidence``,
    ``area``, ``row`` and ``col`` take one value per glyph or none (left out or empty): then
    ``label`` is LABEL_UNKNOWN, ``row``/``col`` CELL_UNKNOWN, ``confidence`` and ``area`` 0,
    the same rule a SymbolArray follows.  ``patches`` is (N, s, s) uint8 or None.
    """

    u: np.ndarray
    v: np.ndarray
    label: np.ndarray = field(default_factory=_not_carried)
    confidence: np.ndarray = field(default_factory=_not_carried)
    spacing_px: float = 0.0
    image_width: int = 0
    image_height: int = 0
    area: np.ndarray = field(default_factory=_not_carried)
    patches: np.ndarray | None = None
    row: np.ndarray = field(default_factory=_not_carried)
    col: np.ndarray = field(default_factory=_not_carried)
    lattice: Any = None
    """The glyphs' lattice (a :class:`~tactile_sl_decoder.decode.grid.Grid`,
    :func:`~tactile_sl_decoder.decode.joint.image_lattice`), if the pipeline built it already
    (in a worker thread); else decoding builds it."""
    rectified: np.ndarray | None = None
    """(N, 2) undistorted + rectified pixels of (u, v), if a worker computed them already."""

    def __post_init__(self) -> None:
        self.u = np.asarray(self.u, dtype=np.float32).reshape(-1)
        self.v = np.asarray(self.v, dtype=np.float32).reshape(-1)
        n = len(self.u)
        if len(self.v) != n:
            raise PipelineInputError(f"glyph arrays differ in length (u {n}, v {len(self.v)})")
        self.label = _field(self.label, n, np.uint8, LABEL_UNKNOWN, "label")
        self.confidence = _field(self.confidence, n, np.float32, 0.0, "confidence")
        self.area = _field(self.area, n, np.float32, 0.0, "area")
        self.row = _field(self.row, n, np.int32, CELL_UNKNOWN, "row")
        self.col = _field(self.col, n, np.int32, CELL_UNKNOWN, "col")
        if self.patches is not None:
            self.patches = np.asarray(self.patches, dtype=np.uint8)
            shape = self.patches.shape
            if len(shape) != 3 or shape[0] != n or shape[1] != shape[2]:
                raise PipelineInputError(f"glyph patches have shape {shape}, expected "
                                         f"({n}, s, s)")

    @classmethod
    def from_detections(cls, det: Detections, image_shape: tuple[int, ...],
                        label: ArrayLike | None = None, confidence: ArrayLike | None = None,
                        row: ArrayLike | None = None, col: ArrayLike | None = None,
                        with_patches: bool = True) -> Glyphs:
        """Extraction output of one (H, W) image, with whatever later stages already know.

        ``label``/``confidence``/``row``/``col``: one value per glyph, or None for the
        defaults (unclassified, undecoded).  ``with_patches=False`` leaves the patches out.
        """
        def given(value: ArrayLike | None) -> np.ndarray:
            return _not_carried() if value is None else np.asarray(value)
        return cls(det.u, det.v, given(label), given(confidence), float(det.spacing_px),
                   int(image_shape[1]), int(image_shape[0]), det.area,
                   det.patches if with_patches else None, given(row), given(col))

    def to_detections(self) -> Detections:
        """Back to the extraction record (no patches carried: an empty patch array)."""
        patches = self.patches
        if patches is None:
            patches = np.zeros((0, PATCH_SIZE, PATCH_SIZE), np.uint8)
        return Detections(self.u, self.v, self.area, self.spacing_px, patches)

    def __len__(self) -> int:
        return len(self.u)

    @property
    def decoded(self) -> np.ndarray:
        """Mask of glyphs with a cell."""
        return self.row >= 0


def _field(value: Any, n: int, dtype: Any, fill: Any, name: str) -> np.ndarray:
    """``value`` as n values of ``dtype``; None or empty (not carried) gives n x ``fill``."""
    arr = np.zeros(0, dtype) if value is None else np.asarray(value, dtype=dtype).reshape(-1)
    if len(arr) == 0:
        return np.full(n, fill, dtype=dtype)
    if len(arr) != n:
        raise PipelineInputError(f"glyph field {name!r} has {len(arr)} values, expected {n}")
    return arr
