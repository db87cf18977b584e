"""Printable artwork: SVG in millimetres and PNG at a chosen resolution, plus a sidecar.

The artwork is the printed pad (contract), so glyph geometry comes only from
:mod:`.shapes`. PNG pixels are area-sampled (``supersample``^2 points per pixel), so the
grey-level ink centroid of every glyph lies on its cell centre to a small fraction of a
pixel. Pixel convention of the sidecar: pixel (x, y) has its centre at (x, y), x right,
y down (OpenCV); so cell (r, c) is at ``cell00_px + (c, r) * pitch_px``.
"""
from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .fileio import Pattern
from .shapes import INK_AREA, Glyph, glyph

MM_PER_INCH = 25.4
DEFAULT_MARGIN_PITCH = 1.5
MARK_STROKE = 0.06   # orientation mark stroke, pitch units: thin so blob filters skip it
MARK_CORNER = -0.9   # its corner, pitch units from cell (0, 0)
MARK_ARM = 0.7


@dataclass(frozen=True)
class Layout:
    """Where the array sits in the artwork, in pitch units and in output units."""

    rows: int
    cols: int
    margin: float  # pitch units

    def size(self, pitch: float) -> tuple[float, float]:
        """Artwork width and height for a given pitch (mm or px)."""
        return ((self.cols - 1 + 2 * self.margin) * pitch,
                (self.rows - 1 + 2 * self.margin) * pitch)


def _mark_rects() -> list[tuple[float, float, float, float]]:
    """The orientation mark: an L in the top-left margin (x0, y0, x1, y1), pitch units.

    Its corner points to cell (0, 0), so a mirrored or rotated view is recognisable.
    """
    x0 = y0 = MARK_CORNER
    return [(x0, y0, x0 + MARK_ARM, y0 + MARK_STROKE),
            (x0, y0, x0 + MARK_STROKE, y0 + MARK_ARM)]


def render_svg(pattern: Pattern, path: str | Path,
               margin_pitch: float = DEFAULT_MARGIN_PITCH) -> None:
    """Write the artwork as SVG with millimetre user units (print at 100 %)."""
    pitch_mm = pattern.pitch_m * 1000.0
    layout = Layout(pattern.rows, pattern.cols, margin_pitch)
    width, height = layout.size(pitch_mm)
    off = margin_pitch * pitch_mm
    glyphs: list[Glyph] = [glyph(name) for name in pattern.primitives]
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.4f}mm" height="{height:.4f}mm" '
        f'viewBox="0 0 {width:.5f} {height:.5f}">',
        f"<!-- tactile-sl pattern {pattern.rows}x{pattern.cols}, "
        f"{pattern.constraints.describe()}, pitch {pitch_mm} mm; cell (0,0) centre at "
        f"({off:.4f} mm, {off:.4f} mm) -->",
        f'<rect x="0" y="0" width="{width:.5f}" height="{height:.5f}" fill="white"/>',
        '<g fill="black" stroke="none">',
    ]
    for x0, y0, x1, y1 in _mark_rects():
        out.append(f'<rect x="{off + x0 * pitch_mm:.5f}" y="{off + y0 * pitch_mm:.5f}" '
                   f'width="{(x1 - x0) * pitch_mm:.5f}" height="{(y1 - y0) * pitch_mm:.5f}"/>')
    for r in range(pattern.rows):
        for c in range(pattern.cols):
            g = glyphs[int(pattern.array[r, c])]
            out.extend(g.svg_elements(off + c * pitch_mm, off + r * pitch_mm, pitch_mm))
    out += ["</g>", "</svg>", ""]
    Path(path).write_text("\n".join(out), encoding="utf-8")


def render_array(pattern: Pattern, pitch_px: float, margin_pitch: float = DEFAULT_MARGIN_PITCH,
                 supersample: int = 8) -> tuple[np.ndarray, dict[str, Any]]:
    """Rasterise the artwork: (uint8 image, dark ink on white; layout facts for the sidecar)."""
    if pitch_px < 4:
        raise ValueError(f"pitch of {pitch_px:.2f} px is too small to draw glyphs (need >= 4)")
    layout = Layout(pattern.rows, pattern.cols, margin_pitch)
    width_f, height_f = layout.size(pitch_px)
    width, height = int(math.ceil(width_f)), int(math.ceil(height_f))
    origin = margin_pitch * pitch_px - 0.5  # pixel centres at integers
    ink = np.zeros((height, width), dtype=np.float32)
    glyphs = [glyph(name) for name in pattern.primitives]
    half = int(math.ceil(0.5 * pitch_px)) + 1
    quant = 64  # sub-pixel offsets are quantised to 1/64 px for the tile cache
    # small glyphs need finer area sampling to keep the ink centroid error << 0.1 px
    supersample = max(supersample, int(math.ceil(384.0 / pitch_px)))
    cache: dict[tuple[int, int, int], np.ndarray] = {}
    for r in range(pattern.rows):
        cy = origin + r * pitch_px
        iy = int(math.floor(cy + 0.5))
        qy = int(round((cy - iy) * quant))
        for c in range(pattern.cols):
            cx = origin + c * pitch_px
            ix = int(math.floor(cx + 0.5))
            qx = int(round((cx - ix) * quant))
            v = int(pattern.array[r, c])
            key = (v, qx, qy)
            tile = cache.get(key)
            if tile is None:
                tile = _coverage_xy(glyphs[v], pitch_px, qx / quant, qy / quant, half,
                                    supersample)
                cache[key] = tile
            y0, x0 = iy - half, ix - half
            ys = slice(max(y0, 0), min(y0 + tile.shape[0], height))
            xs = slice(max(x0, 0), min(x0 + tile.shape[1], width))
            ink[ys, xs] = np.maximum(
                ink[ys, xs], tile[ys.start - y0:ys.stop - y0, xs.start - x0:xs.stop - x0])
    # orientation mark, area-sampled the same way
    yy, xx = np.mgrid[0:height, 0:width]
    for mark_x0, mark_y0, mark_x1, mark_y1 in _mark_rects():
        px0, px1 = origin + mark_x0 * pitch_px, origin + mark_x1 * pitch_px
        py0, py1 = origin + mark_y0 * pitch_px, origin + mark_y1 * pitch_px
        cov_x = np.clip(np.minimum(xx + 0.5, px1) - np.maximum(xx - 0.5, px0), 0, 1)
        cov_y = np.clip(np.minimum(yy + 0.5, py1) - np.maximum(yy - 0.5, py0), 0, 1)
        ink = np.maximum(ink, (cov_x * cov_y).astype(np.float32))
    image = np.round(255.0 * (1.0 - ink)).astype(np.uint8)
    mark = _mark_rects()
    facts = {
        "cell00_px": [round(origin, 6), round(origin, 6)],
        "pitch_px": round(float(pitch_px), 6),
        "width_px": width,
        "height_px": height,
        "orientation_mark_px": [
            round(origin + min(m[0] for m in mark) * pitch_px, 3),
            round(origin + min(m[1] for m in mark) * pitch_px, 3),
            round(origin + max(m[2] for m in mark) * pitch_px, 3),
            round(origin + max(m[3] for m in mark) * pitch_px, 3)],
    }
    return image, facts


def _coverage_xy(g: Glyph, pitch_px: float, fx: float, fy: float, half: int,
                 supersample: int) -> np.ndarray:
    """Coverage tile with the glyph centre at (half + fx, half + fy) tile pixels."""
    s = supersample
    sub = (np.arange(s) + 0.5) / s - 0.5
    px = np.arange(-half, half + 1, dtype=np.float64)
    pts = (px[:, None] + sub[None, :]).ravel()
    x = (pts[None, :] - fx) / pitch_px
    y = (pts[:, None] - fy) / pitch_px
    inside = g.inside(x, y).astype(np.float32)
    n = 2 * half + 1
    return inside.reshape(n, s, n, s).mean(axis=(1, 3))


def write_png(image: np.ndarray, path: str | Path, dpi: float | None = None) -> None:
    """Write an 8-bit greyscale PNG (with a pHYs chunk when the DPI is known)."""
    height, width = image.shape
    raw = b"".join(b"\x00" + image[y].tobytes() for y in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    parts = [b"\x89PNG\r\n\x1a\n",
             chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))]
    if dpi:
        ppm = int(round(dpi / 0.0254))
        parts.append(chunk(b"pHYs", struct.pack(">IIB", ppm, ppm, 1)))
    parts += [chunk(b"IDAT", zlib.compress(raw, 9)), chunk(b"IEND", b"")]
    Path(path).write_bytes(b"".join(parts))


def render_png(pattern: Pattern, path: str | Path, dpi: float | None = None,
               pitch_px: float | None = None, margin_pitch: float = DEFAULT_MARGIN_PITCH,
               supersample: int = 8) -> dict[str, Any]:
    """Write the PNG and its ``PATH.yaml`` sidecar; returns the sidecar contents.

    Give either ``dpi`` (physical print resolution) or ``pitch_px`` (pixels per pitch).
    """
    if dpi is not None and pitch_px is None:
        pitch_px = pattern.pitch_m * 1000.0 / MM_PER_INCH * dpi
    elif pitch_px is not None and dpi is None:
        dpi = pitch_px / (pattern.pitch_m * 1000.0 / MM_PER_INCH)
    else:
        raise ValueError("give exactly one of dpi or pitch_px")
    image, facts = render_array(pattern, pitch_px, margin_pitch, supersample)
    write_png(image, path, dpi)
    sidecar = {
        "tactile_sl_artwork": 1,
        "image": Path(path).name,
        **facts,
        "pitch_m": float(pattern.pitch_m),
        "dpi": round(float(dpi), 4),
        "rows": pattern.rows,
        "cols": pattern.cols,
        "symbols": pattern.constraints.symbols,
        "window": list(pattern.constraints.window),
        "min_hamming": pattern.constraints.min_hamming,
        "primitives": list(pattern.primitives),
        "values_meaning": {i: name for i, name in enumerate(pattern.primitives)},
        "mirrored": False,
        "ink": "dark on white (0 = full ink, 255 = paper), area-sampled",
        "pixel_convention": "pixel (x, y) centre at (x, y); x right, y down; "
                            "cell (r, c) centre = cell00_px + (c, r) * pitch_px",
        "glyph_ink_area_pitch2": INK_AREA,
        "margin_pitch": margin_pitch,
        "array": ["".join(str(int(v)) for v in row) for row in pattern.array],
    }
    Path(str(path) + ".yaml").write_text(
        yaml.safe_dump(sidecar, sort_keys=False, default_flow_style=None, width=4096),
        encoding="utf-8")
    return sidecar
