"""Detections (+ labels, confidences, cells) <-> tactile_sl_msgs/SymbolArray, without rclpy.

Nodes fill an rclpy message with :func:`fill_message`; offline tools and bags use the dict
form of :func:`to_fields`; both read back with :func:`from_message` (duck typing on the
fields, so rclpy messages, bag-decoded objects and dicts all work).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_sl_decoder.contract import CELL_UNKNOWN, LABEL_UNKNOWN, PATCH_SIZE
from tactile_sl_decoder.extract.extraction import Detections


class SymbolArrayError(ValueError):
    """A SymbolArray whose arrays disagree in length or whose patches do not fit."""


@dataclass
class Symbols:
    """One image's glyphs as flat arrays, as carried by a SymbolArray."""

    u: np.ndarray
    v: np.ndarray
    area: np.ndarray
    label: np.ndarray
    confidence: np.ndarray
    row: np.ndarray
    col: np.ndarray
    spacing_px: float = 0.0
    patches: np.ndarray | None = None  # (N, s, s) uint8 or None
    image_width: int = 0
    image_height: int = 0

    def __len__(self) -> int:
        return int(self.u.shape[0])

    @staticmethod
    def from_detections(det: Detections, image_shape: tuple[int, int],
                        label: np.ndarray | None = None, confidence: np.ndarray | None = None,
                        row: np.ndarray | None = None, col: np.ndarray | None = None,
                        with_patches: bool = True) -> Symbols:
        """Wrap extraction output; unknown labels/cells get the message's sentinels."""
        n = len(det)
        return Symbols(
            det.u.astype(np.float32), det.v.astype(np.float32), det.area.astype(np.float32),
            _or(label, n, np.uint8, LABEL_UNKNOWN), _or(confidence, n, np.float32, 0.0),
            _or(row, n, np.int32, CELL_UNKNOWN), _or(col, n, np.int32, CELL_UNKNOWN),
            float(det.spacing_px), det.patches if with_patches else None,
            int(image_shape[1]), int(image_shape[0]))

    def to_detections(self) -> Detections:
        """Back to the extraction dataclass (patches empty if none were carried)."""
        patches = self.patches
        if patches is None:
            patches = np.zeros((0, PATCH_SIZE, PATCH_SIZE), np.uint8)
        return Detections(self.u, self.v, self.area, self.spacing_px, patches)


def _or(value: np.ndarray | None, n: int, dtype: Any, fill: Any) -> np.ndarray:
    if value is None:
        return np.full(n, fill, dtype)
    out = np.asarray(value).astype(dtype, copy=False).reshape(-1)
    if len(out) != n:
        raise SymbolArrayError(f"array of {len(out)} values for {n} glyphs")
    return out


def to_fields(sym: Symbols, header: Any = None) -> dict[str, Any]:
    """SymbolArray fields as a dict of plain values (bags, tests, ``fill_message``)."""
    if sym.patches is not None and len(sym.patches):
        patch_size = int(sym.patches.shape[1])
        patches = np.ascontiguousarray(sym.patches, np.uint8).tobytes()
    else:
        patch_size, patches = 0, b""
    return {
        "header": header if header is not None else
        {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
        "image_width": int(sym.image_width), "image_height": int(sym.image_height),
        "spacing_px": float(sym.spacing_px),
        "u": sym.u.astype(np.float32), "v": sym.v.astype(np.float32),
        "area": sym.area.astype(np.float32), "label": sym.label.astype(np.uint8),
        "confidence": sym.confidence.astype(np.float32), "row": sym.row.astype(np.int32),
        "col": sym.col.astype(np.int32), "patch_size": patch_size, "patches": patches,
    }


def fill_message(msg: Any, sym: Symbols, header: Any = None) -> Any:
    """Fill an rclpy SymbolArray (arrays assigned as numpy / bytes: fast paths in rclpy)."""
    fields = to_fields(sym)
    if header is not None:
        msg.header = header
    for key, value in fields.items():
        if key == "header":
            continue
        if key == "patches":
            value = np.frombuffer(value, np.uint8) if value else np.zeros(0, np.uint8)
        setattr(msg, key, value)
    return msg


def _get(msg: Any, key: str) -> Any:
    return msg[key] if isinstance(msg, dict) else getattr(msg, key)


def from_message(msg: Any) -> Symbols:
    """Read a SymbolArray (rclpy, bag-decoded or dict); inconsistent arrays raise."""
    u = np.asarray(_get(msg, "u"), np.float32).reshape(-1)
    n = len(u)
    arrays = {}
    for key, dtype in (("v", np.float32), ("area", np.float32), ("label", np.uint8),
                       ("confidence", np.float32), ("row", np.int32), ("col", np.int32)):
        value = _get(msg, key)
        if isinstance(value, (bytes, bytearray, memoryview)):
            arr = np.frombuffer(value, dtype)
        else:
            arr = np.asarray(value, dtype).reshape(-1)
        if len(arr) != n:
            raise SymbolArrayError(f"SymbolArray field {key} has {len(arr)} values, u has {n}")
        arrays[key] = arr
    size = int(_get(msg, "patch_size"))
    raw = _get(msg, "patches")
    data = np.frombuffer(bytes(raw), np.uint8) if not isinstance(raw, np.ndarray) else \
        raw.astype(np.uint8, copy=False).reshape(-1)
    patches = None
    if size > 0:
        if data.size != n * size * size:
            raise SymbolArrayError(f"SymbolArray carries {data.size} patch bytes, expected "
                                   f"{n} x {size} x {size} = {n * size * size}")
        patches = data.reshape(n, size, size)
    elif data.size:
        raise SymbolArrayError("SymbolArray has patch bytes but patch_size 0")
    return Symbols(u, arrays["v"], arrays["area"], arrays["label"], arrays["confidence"],
                   arrays["row"], arrays["col"], float(_get(msg, "spacing_px")), patches,
                   int(_get(msg, "image_width")), int(_get(msg, "image_height")))
