"""One frame for the page as one binary WebSocket message: a JSON header and typed blobs.

Layout (little endian): ``b"TSLV"``, uint32 header length, the UTF-8 JSON header padded
with spaces to a multiple of 4 bytes, then the blobs, each starting at a multiple of 4 so
that the page reads them as ``Float32Array`` / ``Uint8Array`` views without copying.  The
header lists every blob as ``{"name", "dtype", "shape", "offset", "length"}`` (``dtype``
``jpeg`` for an encoded image; offsets from the start of the message).

:class:`PacketBuilder` converts a frame's messages (:mod:`.view_model`) and encodes them
only when a page asks for the next frame, and once per frame however many pages ask.
"""
from __future__ import annotations

import json
import struct
import threading
from collections import OrderedDict
from typing import Any, Callable

import cv2
import numpy as np

from .assembly import FrameParts
from .view_model import (
    PadGeometry,
    contact_cells,
    contact_view,
    depth_view,
    diagnostics_view,
    glyph_view,
    image_view,
    pressure_grid,
    slip_view,
    wrench_view,
)

MAGIC = b"TSLV"
MAPS = ("pressure", "depth")


def pack(header: dict[str, Any], blobs: list[tuple[str, Any, str]]) -> bytes:
    """The message: ``blobs`` are (name, bytes or numpy array, dtype name)."""
    payloads = []
    entries = []
    for name, data, dtype in blobs:
        if isinstance(data, np.ndarray):
            shape = list(data.shape)
            raw = np.ascontiguousarray(data, dtype=np.dtype(dtype).newbyteorder("<")).tobytes()
        else:
            shape, raw = [len(data)], bytes(data)
        entries.append({"name": name, "dtype": dtype, "shape": shape, "length": len(raw)})
        payloads.append(raw)
    # offsets depend on the header's length, which depends on the offsets' digits: fix the
    # header size with placeholders first, then write the real offsets (never longer)
    for entry in entries:
        entry["offset"] = 0xFFFFFFFF
    text = json.dumps({**header, "blobs": entries}, separators=(",", ":"))
    size = 8 + len(text.encode())
    size += (-size) % 4
    offset = size
    for entry, raw in zip(entries, payloads):
        entry["offset"] = offset
        offset += len(raw) + (-len(raw)) % 4
    encoded = json.dumps({**header, "blobs": entries}, separators=(",", ":")).encode()
    encoded += b" " * (size - 8 - len(encoded))
    parts = [MAGIC, struct.pack("<I", len(encoded)), encoded]
    for raw in payloads:
        parts += [raw, b"\0" * ((-len(raw)) % 4)]
    return b"".join(parts)


def unpack(message: bytes) -> tuple[dict[str, Any], dict[str, Any]]:
    """(header, {name: numpy array or bytes}) of a message (tests, benchmarks)."""
    if message[:4] != MAGIC:
        raise ValueError("not a viewer frame message")
    (length,) = struct.unpack_from("<I", message, 4)
    header = json.loads(message[8: 8 + length])
    blobs: dict[str, Any] = {}
    for entry in header["blobs"]:
        raw = message[entry["offset"]: entry["offset"] + entry["length"]]
        if entry["dtype"] == "jpeg":
            blobs[entry["name"]] = raw
        else:
            blobs[entry["name"]] = np.frombuffer(raw, np.dtype(entry["dtype"]).newbyteorder(
                "<")).reshape(entry["shape"])
    return header, blobs


def encode_jpeg(gray: np.ndarray, quality: int) -> bytes:
    """JPEG of a grey image (OpenCV)."""
    ok, data = cv2.imencode(".jpg", gray, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return data.tobytes()


def stamp_text(stamp_ns: int) -> str:
    """``sec.nanosec`` (exact; JavaScript numbers cannot hold nanoseconds since 1970)."""
    return f"{stamp_ns // 1_000_000_000}.{stamp_ns % 1_000_000_000:09d}"


class PacketBuilder:
    """Frame messages -> page message, with each part converted once per stamp.

    Bad parts (a message the view cannot read) are left out with their reason in the
    header's ``errors`` (the page shows it; ``on_error`` logs it), never raised.
    """

    def __init__(self, pad: PadGeometry, sensor: str = "", jpeg_quality: int = 80,
                 min_pressure_scale_kpa: float = 10.0,
                 on_error: Callable[[str], None] | None = None) -> None:
        self.pad = pad
        self.sensor = sensor
        self.jpeg_quality = int(jpeg_quality)
        self.min_pressure_scale_kpa = float(min_pressure_scale_kpa)
        self.on_error = on_error
        self._cache: OrderedDict[tuple[str, int, int], Any] = OrderedDict()
        self._lock = threading.Lock()
        self.encoded = 0       # images JPEG-encoded (the benchmark reads it)

    def _part(self, name: str, frame: FrameParts, convert: Callable[[Any], Any],
              errors: list[str]) -> Any:
        msg = frame.parts.get(name)
        if msg is None:
            return None
        key = (name, frame.stamp_ns, id(msg))
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
        try:
            value = convert(msg)
        except (ValueError, TypeError, AttributeError, KeyError) as exc:
            text = f"{name}: {exc}"
            errors.append(text)
            if self.on_error is not None:
                self.on_error(text)
            value = None
        with self._lock:
            self._cache[key] = value
            while len(self._cache) > 32:
                self._cache.popitem(last=False)
        return value

    def _jpeg(self, msg: Any) -> tuple[bytes, int, int]:
        gray = image_view(msg)
        self.encoded += 1
        return encode_jpeg(gray, self.jpeg_quality), gray.shape[1], gray.shape[0]

    def build(self, frame: FrameParts | None, stats: dict[str, Any], map_kind: str = "pressure",
              diagnostics: Any = None, extra: dict[str, Any] | None = None) -> bytes:
        """The page message of ``frame`` (None: figures only) with the current figures."""
        errors: list[str] = []
        header: dict[str, Any] = {"type": "frame", "stats": stats, **(extra or {})}
        if diagnostics is not None:
            try:
                header["diagnostics"] = diagnostics_view(diagnostics, self.sensor)
            except (ValueError, TypeError, AttributeError, IndexError) as exc:
                errors.append(f"diagnostics: {exc}")
        blobs: list[tuple[str, Any, str]] = []
        if frame is None:
            header["errors"] = errors
            return pack(header, blobs)
        header["stamp"] = stamp_text(frame.stamp_ns)
        header["parts"] = sorted(frame.parts)
        image = self._part("image", frame, self._jpeg, errors)
        if image is not None:
            blobs.append(("image", image[0], "jpeg"))
            header["image"] = {"width": image[1], "height": image[2]}
        glyphs = self._part("glyphs", frame, glyph_view, errors)
        if glyphs is not None:
            blobs += [(f"glyph_{k}", v, v.dtype.str.lstrip("<|=")) for k, v in glyphs.items()]
            header["glyphs"] = {"count": int(len(glyphs["u"])),
                                "decoded": int(glyphs["decoded"].sum())}
        points = frame.parts.get("points")
        if points is not None:
            header["points"] = int(points.width) * int(points.height)
        for name, convert in (("wrench", wrench_view), ("contact", contact_view),
                              ("slip", slip_view)):
            value = self._part(name, frame, convert, errors)
            if value is not None:
                header[name] = value
        self._add_map(frame, map_kind if map_kind in MAPS else "pressure", header, blobs,
                      errors)
        header["errors"] = errors
        return pack(header, blobs)

    def _add_map(self, frame: FrameParts, map_kind: str, header: dict[str, Any],
                 blobs: list[tuple[str, Any, str]], errors: list[str]) -> None:
        """The pressure grid (kPa) with the contact cells, or the depth map (um)."""
        header["pad"] = self.pad.to_json()
        if map_kind == "depth":
            depth = self._part("depth", frame, depth_view, errors)
            if depth is not None:
                blobs.append(("depth", depth, "f4"))
                peak = float(np.nanmax(depth)) if np.isfinite(depth).any() else 0.0
                header["map"] = {"kind": "depth", "unit": "um",
                                 "vmax": max(peak, 1.0), "shape": list(depth.shape)}
            return
        pressure = self._part("field", frame, lambda m: pressure_grid(m, self.pad), errors)
        if pressure is None:
            return
        blobs.append(("pressure", pressure, "f4"))
        contact = header.get("contact")
        if contact is not None:
            blobs.append(("contact_cells",
                          contact_cells(pressure, contact["cells_in_contact"]), "u1"))
        peak = float(np.nanmax(pressure)) if np.isfinite(pressure).any() else 0.0
        header["map"] = {"kind": "pressure", "unit": "kPa",
                         "vmax": max(peak, self.min_pressure_scale_kpa),
                         "shape": list(pressure.shape)}

