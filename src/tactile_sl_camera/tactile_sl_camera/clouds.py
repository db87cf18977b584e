"""The contract's PointCloud2 layout (x, y, z FLOAT32 metres; row, col INT32), without rclpy.

One packed record per glyph cell: 20 bytes, little endian, unorganised (height 1), dense.
``cloud_fields`` gives the message fields as a dict (for bags and for filling rclpy
messages); ``cloud_to_arrays`` reads any PointCloud2 that has these fields back.
"""
from __future__ import annotations

from typing import Any

import numpy as np

# sensor_msgs/PointField datatypes
INT32 = 5
FLOAT32 = 7

POINT_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("row", "<i4"), ("col", "<i4")])
POINT_FIELDS = [
    {"name": "x", "offset": 0, "datatype": FLOAT32, "count": 1},
    {"name": "y", "offset": 4, "datatype": FLOAT32, "count": 1},
    {"name": "z", "offset": 8, "datatype": FLOAT32, "count": 1},
    {"name": "row", "offset": 12, "datatype": INT32, "count": 1},
    {"name": "col", "offset": 16, "datatype": INT32, "count": 1},
]
_NUMPY_OF_DATATYPE = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


class CloudFormatError(ValueError):
    """A PointCloud2 without the contract's fields, or with inconsistent sizes."""


def pack_points(xyz: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Structured array of points; rejects non-finite coordinates and duplicate cells."""
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    rows = np.asarray(rows).reshape(-1)
    cols = np.asarray(cols).reshape(-1)
    if not (len(xyz) == len(rows) == len(cols)):
        raise CloudFormatError("xyz, rows and cols differ in length")
    if not np.isfinite(xyz).all():
        raise CloudFormatError("non-finite point coordinates (the cloud must be dense)")
    if len(rows) and len(np.unique(rows.astype(np.int64) * 1_000_003 + cols)) != len(rows):
        raise CloudFormatError("two points for the same cell")
    points = np.empty(len(xyz), dtype=POINT_DTYPE)
    points["x"], points["y"], points["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    points["row"], points["col"] = rows, cols
    return points


def cloud_fields(points: np.ndarray, stamp: tuple[int, int], frame_id: str) -> dict[str, Any]:
    """PointCloud2 fields (as a dict) for packed points, stamped exactly (sec, nanosec)."""
    points = np.ascontiguousarray(points, dtype=POINT_DTYPE)
    return {
        "header": {"stamp": {"sec": int(stamp[0]), "nanosec": int(stamp[1])},
                   "frame_id": frame_id},
        "height": 1,
        "width": len(points),
        "fields": [dict(f) for f in POINT_FIELDS],
        "is_bigendian": False,
        "point_step": POINT_DTYPE.itemsize,
        "row_step": POINT_DTYPE.itemsize * len(points),
        "data": points.tobytes(),
        "is_dense": True,
    }


def cloud_to_arrays(msg: Any) -> np.ndarray:
    """Structured (x, y, z, row, col) array from a PointCloud2 (rclpy or bag-decoded)."""
    names = {}
    for field in msg.fields:
        name = field["name"] if isinstance(field, dict) else field.name
        offset = field["offset"] if isinstance(field, dict) else field.offset
        datatype = field["datatype"] if isinstance(field, dict) else field.datatype
        names[name] = (offset, datatype)
    missing = [n for n in POINT_DTYPE.names if n not in names]
    if missing:
        raise CloudFormatError(f"PointCloud2 lacks field(s) {', '.join(missing)}")
    count = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    data = msg.data
    raw = np.frombuffer(data if isinstance(data, (bytes, bytearray, memoryview))
                        else bytes(data), dtype=np.uint8)
    if raw.size < count * step:
        raise CloudFormatError(f"PointCloud2 data has {raw.size} bytes, expected {count * step}")
    endian = ">" if msg.is_bigendian else "<"
    dtype = np.dtype({"names": list(POINT_DTYPE.names),
                      "formats": [endian + _NUMPY_OF_DATATYPE[names[n][1]]
                                  for n in POINT_DTYPE.names],
                      "offsets": [names[n][0] for n in POINT_DTYPE.names],
                      "itemsize": step})
    view = np.frombuffer(raw[: count * step].tobytes(), dtype=dtype)
    out = np.empty(count, dtype=POINT_DTYPE)
    for name in POINT_DTYPE.names:
        out[name] = view[name]
    return out
