"""The contract's PointCloud2 layouts, without rclpy.

Points (x, y, z FLOAT32 metres; row, col INT32): one packed record per glyph cell, 20 bytes,
little endian, unorganised (height 1), dense. The touch ``field`` (pad frame): x, y, z
(current position), dx, dy, dz (displacement from the reference) FLOAT32, row, col INT32, and
optionally fx, fy, fz FLOAT32 (N): 32 or 44 bytes. ``cloud_fields`` gives the message fields
as a dict (for bags and for filling rclpy messages); ``cloud_to_arrays`` reads any
PointCloud2 that has the wanted fields back.
"""
from __future__ import annotations

from collections.abc import Mapping
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
_DATATYPE_OF_NUMPY = {v: k for k, v in _NUMPY_OF_DATATYPE.items()}
FIELD_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("dx", "<f4"), ("dy", "<f4"),
                        ("dz", "<f4"), ("row", "<i4"), ("col", "<i4")])
FIELD_FORCE_DTYPE = np.dtype(FIELD_DTYPE.descr + [("fx", "<f4"), ("fy", "<f4"), ("fz", "<f4")])


class CloudFormatError(ValueError):
    """A PointCloud2 without the contract's fields, or with inconsistent sizes."""


def _names(dtype: np.dtype) -> tuple[str, ...]:
    """Field names of a structured dtype (every layout here is one)."""
    if dtype.names is None:
        raise TypeError(f"{dtype} is not a structured dtype")
    return dtype.names


def pack_points(xyz: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Structured array of points; rejects non-finite coordinates and duplicate cells."""
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    rows = np.asarray(rows).reshape(-1)
    cols = np.asarray(cols).reshape(-1)
    if not (len(xyz) == len(rows) == len(cols)):
        raise CloudFormatError("xyz, rows and cols differ in length")
    if not np.isfinite(xyz).all():
        raise CloudFormatError("non-finite point coordinates (the cloud must be dense)")
    if len(rows) > 1:
        keys = np.sort(rows.astype(np.int64) * 1_000_003 + cols)   # (np.unique: 10x slower)
        if (keys[1:] == keys[:-1]).any():
            raise CloudFormatError("two points for the same cell")
    points = np.empty(len(xyz), dtype=POINT_DTYPE)
    points["x"], points["y"], points["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    points["row"], points["col"] = rows, cols
    return points


def pack_field(xyz: np.ndarray, dxyz: np.ndarray, rows: np.ndarray, cols: np.ndarray,
               force: np.ndarray | None = None) -> np.ndarray:
    """Structured array of the touch ``field`` cloud; ``force`` (N, 3) N appends fx, fy, fz.

    Same checks as :func:`pack_points` (finite, one point per cell, equal lengths).
    """
    points = pack_points(xyz, rows, cols)
    dxyz = np.asarray(dxyz, dtype=np.float64).reshape(-1, 3)
    if len(dxyz) != len(points):
        raise CloudFormatError("xyz and dxyz differ in length")
    if not np.isfinite(dxyz).all():
        raise CloudFormatError("non-finite displacements (the cloud must be dense)")
    out = np.empty(len(points), dtype=FIELD_DTYPE if force is None else FIELD_FORCE_DTYPE)
    for name in _names(POINT_DTYPE):
        out[name] = points[name]
    out["dx"], out["dy"], out["dz"] = dxyz[:, 0], dxyz[:, 1], dxyz[:, 2]
    if force is not None:
        force = np.asarray(force, dtype=np.float64).reshape(-1, 3)
        if len(force) != len(points):
            raise CloudFormatError("xyz and force differ in length")
        if not np.isfinite(force).all():
            raise CloudFormatError("non-finite forces (the cloud must be dense)")
        out["fx"], out["fy"], out["fz"] = force[:, 0], force[:, 1], force[:, 2]
    return out


def _point_fields(dtype: np.dtype) -> list[dict[str, Any]]:
    """PointField dicts of a packed little-endian structured dtype (one value per field)."""
    out = []
    fields: Mapping[str, tuple[Any, ...]] = dtype.fields or {}
    for name in _names(dtype):
        sub, offset = fields[name][:2]
        code = sub.str[1:]
        if sub.byteorder == ">" or code not in _DATATYPE_OF_NUMPY:
            raise CloudFormatError(f"field {name!r} has no PointField type ({sub})")
        out.append({"name": name, "offset": int(offset), "datatype": _DATATYPE_OF_NUMPY[code],
                    "count": 1})
    return out


def cloud_fields(points: np.ndarray, stamp: tuple[int, int], frame_id: str) -> dict[str, Any]:
    """PointCloud2 fields (as a dict) for packed points or a packed field, stamped exactly."""
    if np.asarray(points).dtype.names in (FIELD_DTYPE.names, FIELD_FORCE_DTYPE.names):
        points = np.ascontiguousarray(points)
        fields = _point_fields(points.dtype)
    else:
        points = np.ascontiguousarray(points, dtype=POINT_DTYPE)
        fields = [dict(f) for f in POINT_FIELDS]
    return {
        "header": {"stamp": {"sec": int(stamp[0]), "nanosec": int(stamp[1])},
                   "frame_id": frame_id},
        "height": 1,
        "width": len(points),
        "fields": fields,
        "is_bigendian": False,
        "point_step": points.dtype.itemsize,
        "row_step": points.dtype.itemsize * len(points),
        "data": points.tobytes(),
        "is_dense": True,
    }


def cloud_to_arrays(msg: Any, dtype: np.dtype = POINT_DTYPE) -> np.ndarray:
    """Structured array with ``dtype``'s fields (default x, y, z, row, col) from a PointCloud2.

    Works on rclpy and bag-decoded messages; ``FIELD_DTYPE`` reads a touch field.
    """
    names = {}
    for field in msg.fields:
        name = field["name"] if isinstance(field, dict) else field.name
        offset = field["offset"] if isinstance(field, dict) else field.offset
        datatype = field["datatype"] if isinstance(field, dict) else field.datatype
        names[name] = (offset, datatype)
    wanted = _names(dtype)
    missing = [n for n in wanted if n not in names]
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
    layout = np.dtype({"names": list(wanted),
                       "formats": [endian + _NUMPY_OF_DATATYPE[names[n][1]] for n in wanted],
                       "offsets": [names[n][0] for n in wanted],
                       "itemsize": step})
    view = np.frombuffer(raw[: count * step].tobytes(), dtype=layout)
    out = np.empty(count, dtype=dtype)
    for name in wanted:
        out[name] = view[name]
    return out
