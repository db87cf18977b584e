"""Decoder messages -> what the page draws: small numpy arrays and plain numbers, no rclpy.

Every function takes a message by its fields (duck typing), so rclpy messages, messages
decoded from a bag and the offline decoder's field dicts (wrapped by :func:`as_message`)
give the same view.  Units on the wire to the page: pressure kPa, depth um, force N,
moment N m, lengths m (the page scales them for display); grids are in the pad frame, row
index along +y, column index along +x (the page draws +y upwards, seen from the object).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from tactile_sl_common.clouds import FIELD_FORCE_DTYPE, cloud_to_arrays
from tactile_sl_common.images import to_gray
from tactile_sl_decoder.contract import CELL_UNKNOWN, LABEL_UNKNOWN
from tactile_sl_decoder.symbol_array import from_message

SLIP_STATES = {0: "no contact", 1: "stick", 2: "partial slip", 3: "gross slip"}
"""tactile_sl_msgs/Slip state constants (CONTRACT.md "Slip") as the page names them."""


@dataclass(frozen=True)
class PadGeometry:
    """The pattern's cell grid: what places a field's cells on the pressure map."""

    rows: int
    cols: int
    pitch: float     # m between cell centres

    def to_json(self) -> dict[str, Any]:
        return {"rows": self.rows, "cols": self.cols, "pitch": self.pitch}


def as_message(value: Any) -> Any:
    """Attribute access on nested field dicts (the offline decoder's messages)."""
    if isinstance(value, dict):
        return SimpleNamespace(**{k: as_message(v) for k, v in value.items()})
    if isinstance(value, list):
        return [as_message(v) for v in value]
    return value


def stamp_of(msg: Any) -> int:
    """Header stamp in nanoseconds (exact integers)."""
    stamp = msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def image_view(msg: Any) -> np.ndarray:
    """Grey levels of an Image (mono8, bgr8, rgb8, ...), copied out of the message."""
    return np.array(to_gray(msg), dtype=np.uint8, copy=True)


def glyph_view(msg: Any) -> dict[str, np.ndarray]:
    """A SymbolArray's glyph centres (px), labels (255 = unknown) and decoded flags."""
    glyphs = from_message(msg)
    n = len(glyphs.u)
    label = glyphs.label if len(glyphs.label) == n else np.full(n, LABEL_UNKNOWN, np.uint8)
    row = glyphs.row if len(glyphs.row) == n else np.full(n, CELL_UNKNOWN, np.int32)
    return {"u": np.asarray(glyphs.u, np.float32), "v": np.asarray(glyphs.v, np.float32),
            "label": np.asarray(label, np.uint8),
            "decoded": (np.asarray(row) != CELL_UNKNOWN).astype(np.uint8)}


def pressure_grid(field_msg: Any, pad: PadGeometry) -> np.ndarray:
    """Normal pressure (kPa) per cell on the (rows, cols) grid; NaN where nothing decoded.

    A cell's pressure is its pressing force over its area, max(0, -fz) / pitch^2 (as
    ``tactile_sl_decoder.tooling.pictures.render_pressure`` draws it); the cell is placed by
    its rest position (x - dx, y - dy) in the pad frame, so a mirrored sensor needs nothing
    special.  A field without forces (fx, fy, fz) raises CloudFormatError.
    """
    cells = cloud_to_arrays(field_msg, FIELD_FORCE_DTYPE)
    grid = np.full((pad.rows, pad.cols), np.nan, np.float32)
    if not len(cells) or pad.pitch <= 0:
        return grid
    rest_x = cells["x"].astype(np.float64) - cells["dx"]
    rest_y = cells["y"].astype(np.float64) - cells["dy"]
    j = np.rint(rest_x / pad.pitch + (pad.cols - 1) / 2.0).astype(np.int64)
    i = np.rint(rest_y / pad.pitch + (pad.rows - 1) / 2.0).astype(np.int64)
    inside = (i >= 0) & (i < pad.rows) & (j >= 0) & (j < pad.cols)
    press = np.maximum(-cells["fz"].astype(np.float64), 0.0) / pad.pitch ** 2 / 1e3
    grid[i[inside], j[inside]] = press[inside]
    return grid


def contact_cells(pressure_kpa: np.ndarray, cells_in_contact: int) -> np.ndarray:
    """The cells the decoder counted into the contact area (uint8 mask on the grid).

    The decoder counts every cell that presses by more than a fraction of the peak (in a
    region that has one), so its ``cells_in_contact`` cells are the most pressed ones: the
    mask marks the ``cells_in_contact`` largest pressures (ties at the cut go in).
    """
    mask = np.zeros(pressure_kpa.shape, np.uint8)
    count = int(cells_in_contact)
    flat = np.where(np.isfinite(pressure_kpa), pressure_kpa, -np.inf).ravel()
    pressing = int((flat > 0).sum())
    count = min(count, pressing)
    if count <= 0:
        return mask
    cut = np.partition(flat, flat.size - count)[flat.size - count]
    mask.ravel()[:] = (flat >= cut) & (flat > 0)
    return mask


def depth_view(msg: Any) -> np.ndarray:
    """The 32FC1 depth map as float32 um (indentation, > 0 pressed in; NaN not decoded)."""
    if str(msg.encoding) != "32FC1":
        raise ValueError(f"depth image encoding {msg.encoding!r}, expected 32FC1")
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    order = ">" if int(msg.is_bigendian) else "<"
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if raw.size < step * height or step < 4 * width:
        raise ValueError(f"depth image data has {raw.size} bytes for {width}x{height}, "
                         f"step {step}")
    rows = raw[: step * height].reshape(height, step)[:, : 4 * width]
    metres = np.ascontiguousarray(rows).view(order + "f4").reshape(height, width)
    return (metres.astype(np.float32) * 1e6).astype(np.float32)


def _vec(v: Any) -> list[float]:
    return [float(v.x), float(v.y), float(v.z)]


def _finite(x: float) -> float | None:
    """JSON has no NaN: None instead."""
    return float(x) if math.isfinite(float(x)) else None


def wrench_view(msg: Any) -> dict[str, Any]:
    """Force (N) and moment (N m, about the pad origin) in the pad frame."""
    return {"force": _vec(msg.wrench.force), "torque": _vec(msg.wrench.torque),
            "frame": str(msg.header.frame_id)}


def contact_view(msg: Any) -> dict[str, Any]:
    """The Contact message's numbers (SI units, pad frame)."""
    return {"in_contact": bool(msg.in_contact), "area": float(msg.area),
            "centroid": _vec(msg.centroid), "max_depth": float(msg.max_depth),
            "normal_force": float(msg.normal_force), "shear_force": _vec(msg.shear_force),
            "peak_pressure": float(msg.peak_pressure),
            "cells_in_contact": int(msg.cells_in_contact),
            "regions": [{"force": float(f), "area": float(a), "centroid": _vec(c)}
                        for f, a, c in zip(msg.region_force, msg.region_area,
                                           msg.region_centroid)]}


def slip_view(msg: Any) -> dict[str, Any]:
    """tactile_sl_msgs/Slip: state name, stick ratio, margin, mu, direction (NaN -> None)."""
    state = int(msg.state)
    return {"state": state, "state_name": SLIP_STATES.get(state, f"state {state}"),
            "stick_ratio": _finite(msg.stick_ratio), "slip_margin": _finite(msg.slip_margin),
            "friction_coefficient": _finite(msg.friction_coefficient),
            "direction": _vec(msg.direction)}


LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}


def diagnostics_view(msg: Any, sensor: str, limit: int = 12) -> list[dict[str, Any]]:
    """Statuses of one sensor from a DiagnosticArray (its hardware_id or name prefix).

    ``sensor`` is the namespace or frame prefix without slashes (``tactile``); when no
    status names it, every status is shown (up to ``limit``).
    """
    statuses = list(msg.status)
    mine = [s for s in statuses if str(s.hardware_id) == sensor
            or str(s.name).startswith(sensor + "/")] if sensor else statuses
    out = []
    for s in (mine or statuses)[:limit]:
        raw = s.level
        code = raw[0] if isinstance(raw, (bytes, bytearray)) else int(raw)
        out.append({"name": str(s.name), "level": LEVELS.get(code, str(code)),
                    "message": str(s.message)})
    return out
