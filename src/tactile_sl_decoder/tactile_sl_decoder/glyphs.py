"""Glyphs of one image as flat arrays, and their conversion from SymbolArray (no rclpy)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_sl_decoder.contract import LABEL_UNKNOWN


class PipelineInputError(ValueError):
    """A stereo frame the pipeline cannot process (the message says why)."""


@dataclass
class Glyphs:
    """Glyphs of one image as flat arrays (the SymbolArray fields, without ROS).

    Coordinates are raw (distorted) pixels, OpenCV convention.  ``row``/``col`` are -1 until
    decoded, ``label`` 255 and ``confidence`` 0 until classified.
    """

    u: np.ndarray
    v: np.ndarray
    label: np.ndarray
    confidence: np.ndarray
    spacing_px: float = 0.0
    image_width: int = 0
    image_height: int = 0
    area: np.ndarray | None = None
    patches: np.ndarray | None = None     # (N, P, P) uint8
    row: np.ndarray | None = None
    col: np.ndarray | None = None
    neighbours: tuple[np.ndarray, np.ndarray] | None = None
    """k-NN table of (u, v) (:func:`~tactile_sl_decoder.decode.grid.nearest_neighbours`), if the
    pipeline computed it already (in a worker thread); else decoding computes it."""
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
        self.row = _field(self.row, n, np.int32, -1, "row")
        self.col = _field(self.col, n, np.int32, -1, "col")

    def __len__(self) -> int:
        return len(self.u)

    @property
    def decoded(self) -> np.ndarray:
        """Mask of glyphs with a cell."""
        return self.row >= 0


def _field(value: Any, n: int, dtype: Any, fill: Any, name: str) -> np.ndarray:
    if value is None:
        return np.full(n, fill, dtype=dtype)
    arr = np.asarray(value, dtype=dtype).reshape(-1)
    if len(arr) != n:
        raise PipelineInputError(f"glyph field {name!r} has {len(arr)} values, expected {n}")
    return arr


def _array(value: Any, dtype: Any) -> np.ndarray:
    if isinstance(value, np.ndarray):
        return value.astype(dtype, copy=False).reshape(-1)
    try:
        return np.frombuffer(memoryview(value), dtype=dtype).copy()
    except (TypeError, ValueError):
        return np.asarray(list(value), dtype=dtype)


def glyphs_from_symbol_array(msg: Any) -> Glyphs:
    """Glyphs of a tactile_sl_msgs/SymbolArray (rclpy or bag-decoded), checked."""
    u = _array(msg.u, np.float32)
    n = len(u)
    fields = {"v": np.float32, "area": np.float32, "label": np.uint8,
              "confidence": np.float32, "row": np.int32, "col": np.int32}
    arrays = {}
    for name, dtype in fields.items():
        arr = _array(getattr(msg, name), dtype)
        if len(arr) not in (n, 0) or (name in ("v", "label") and len(arr) != n):
            raise PipelineInputError(f"SymbolArray field {name!r} has {len(arr)} values but "
                                     f"there are {n} glyphs")
        arrays[name] = arr if len(arr) == n else None
    ps = int(msg.patch_size)
    patches = None
    if ps > 0:
        raw = _array(msg.patches, np.uint8)
        if len(raw) == n * ps * ps:
            patches = raw.reshape(n, ps, ps)
    return Glyphs(u, arrays["v"], arrays["label"], arrays["confidence"], float(msg.spacing_px),
                  int(msg.image_width), int(msg.image_height), arrays["area"], patches,
                  arrays["row"], arrays["col"])
