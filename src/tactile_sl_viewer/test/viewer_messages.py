"""Decoder messages for the viewer's unit tests, built with the project's own converters.

Each is a field dict wrapped for attribute access (as the offline decoder's messages are),
so the view reads them exactly as it reads rclpy or bag-decoded messages.
"""
from __future__ import annotations

import numpy as np

from tactile_sl_common.clouds import cloud_fields, pack_field, pack_points
from tactile_sl_common.images import image_fields
from tactile_sl_viewer.view_model import PadGeometry, as_message

PAD = PadGeometry(rows=6, cols=5, pitch=0.0005)


def header(stamp_ns: int, frame_id: str = "tactile_pad") -> dict:
    return {"stamp": {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9},
            "frame_id": frame_id}


def stamp_pair(stamp_ns: int) -> tuple[int, int]:
    return stamp_ns // 10**9, stamp_ns % 10**9


def field(stamp_ns: int, fz_by_cell: dict[tuple[int, int], float], pad: PadGeometry = PAD,
          shift: tuple[float, float] = (0.0, 0.0)):
    """A field cloud: every cell of ``pad`` decoded, moved by ``shift`` (m), with fz (N)."""
    rows, cols = np.mgrid[0:pad.rows, 0:pad.cols]
    rows, cols = rows.ravel(), cols.ravel()
    rest = np.column_stack([(cols - (pad.cols - 1) / 2) * pad.pitch,
                            (rows - (pad.rows - 1) / 2) * pad.pitch, np.zeros(len(rows))])
    moved = np.column_stack([np.full(len(rows), shift[0]), np.full(len(rows), shift[1]),
                             np.zeros(len(rows))])
    force = np.zeros((len(rows), 3))
    for (r, c), fz in fz_by_cell.items():
        force[r * pad.cols + c, 2] = fz
    packed = pack_field(rest + moved, moved, rows, cols, force)
    return as_message(cloud_fields(packed, stamp_pair(stamp_ns), "tactile_pad"))


def points(stamp_ns: int, n: int = 3):
    packed = pack_points(np.ones((n, 3)) * 0.01, np.arange(n), np.zeros(n, int))
    return as_message(cloud_fields(packed, stamp_pair(stamp_ns), "tactile_left_optical_frame"))


def wrench(stamp_ns: int, force=(0.0, 0.0, -1.25), torque=(0.0, 0.0, 0.0)):
    xyz = ("x", "y", "z")
    return as_message({"header": header(stamp_ns),
                       "wrench": {"force": dict(zip(xyz, force)),
                                  "torque": dict(zip(xyz, torque))}})


def contact(stamp_ns: int, cells: int = 1, normal: float = 1.25):
    zero = {"x": 0.0, "y": 0.0, "z": 0.0}
    return as_message({"header": header(stamp_ns), "in_contact": cells > 0, "area": 2.5e-7 * cells,
                       "centroid": zero, "max_depth": 1e-4, "normal_force": normal,
                       "shear_force": zero, "peak_pressure": 5e6, "cells_in_contact": cells,
                       "region_force": [normal], "region_area": [2.5e-7 * cells],
                       "region_centroid": [zero]})


def image(stamp_ns: int, value: int = 128, size: tuple[int, int] = (48, 64)):
    pixels = np.full(size, value, np.uint8)
    pixels[10:20, 10:30] = 255 - value
    return as_message({"header": header(stamp_ns, "tactile_left_optical_frame"),
                       **image_fields(pixels)})


def symbols(stamp_ns: int, n: int = 4):
    return as_message({"header": header(stamp_ns), "image_width": 64, "image_height": 48,
                       "spacing_px": 8.0, "u": np.arange(n, dtype=np.float32) * 5,
                       "v": np.full(n, 7.0, np.float32), "area": np.full(n, 9.0, np.float32),
                       "label": np.array([0, 1, 2, 255][:n] * (n // 4 + 1), np.uint8)[:n],
                       "confidence": np.ones(n, np.float32),
                       "row": np.array([1, -1] * n, np.int32)[:n],
                       "col": np.array([2, -1] * n, np.int32)[:n],
                       "patch_size": 0, "patches": b""})


def depth(stamp_ns: int, metres: np.ndarray, big_endian: bool = False):
    data = np.ascontiguousarray(metres, dtype=">f4" if big_endian else "<f4")
    return as_message({"header": header(stamp_ns), "height": data.shape[0],
                       "width": data.shape[1], "encoding": "32FC1",
                       "is_bigendian": int(big_endian), "step": data.shape[1] * 4,
                       "data": data.tobytes()})
