"""Pictures for tools/demo.py (BGR; OpenCV and numpy only).

Glyphs on a camera image, a cloud, and the touch stage's pressure and depth maps in the
pad frame.
"""
from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from tactile_sl_common.clouds import cloud_to_arrays

# ---------------------------------------------------------------------- camera images, clouds

CLASS_COLOURS_BGR = {0: (60, 60, 230), 1: (60, 200, 60), 2: (230, 140, 40)}
UNKNOWN_COLOUR_BGR = (160, 160, 160)


def render_overlay(gray: np.ndarray, glyphs: Any, label_every: int = 4) -> np.ndarray:
    """BGR picture of one image with its glyphs coloured by class and cells annotated.

    ``glyphs`` has ``u, v, label, row, col`` arrays (a pipeline ``Glyphs``, or
    ``symbol_array.from_message`` of a ``symbols_decoded`` message). Decoded glyphs get a
    filled dot, undecoded ones a ring; every cell whose row and column are multiples of
    ``label_every`` is written as ``row,col``.
    """
    img = cv2.cvtColor(np.ascontiguousarray(gray, np.uint8), cv2.COLOR_GRAY2BGR)
    u = np.asarray(glyphs.u, np.float64)
    v = np.asarray(glyphs.v, np.float64)
    label = np.asarray(glyphs.label)
    row = np.asarray(glyphs.row)
    col = np.asarray(glyphs.col)
    for i in range(len(u)):      # drawing only (no per-glyph work in the pipeline)
        colour = CLASS_COLOURS_BGR.get(int(label[i]), UNKNOWN_COLOUR_BGR)
        centre = (int(round(u[i])), int(round(v[i])))
        cv2.circle(img, centre, 3, colour, -1 if row[i] >= 0 else 1, cv2.LINE_AA)
        if row[i] >= 0 and row[i] % label_every == 0 and col[i] % label_every == 0:
            cv2.putText(img, f"{row[i]},{col[i]}", (centre[0] + 4, centre[1] - 4),
                        cv2.FONT_HERSHEY_PLAIN, 0.8, (0, 255, 255), 1, cv2.LINE_AA)
    return img


def render_cloud(points: np.ndarray | Any, size: tuple[int, int] = (640, 480)) -> np.ndarray:
    """BGR picture of a cloud seen from the cameras; colour = height above the pad's plane.

    The pad is tilted with respect to the (converging) cameras, so the colour is the signed
    distance to the cloud's least-squares plane: red is pressed towards the cameras, blue
    away; the range is written in the corner, in millimetres.
    """
    pts = points if isinstance(points, np.ndarray) else cloud_to_arrays(points)
    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    if len(pts) < 3:
        cv2.putText(img, f"{len(pts)} points", (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.8,
                    (0, 0, 0), 2)
        return img
    xyz = np.column_stack([pts["x"], pts["y"], pts["z"]]).astype(np.float64)
    centre = xyz.mean(axis=0)
    normal = np.linalg.svd(xyz - centre, full_matrices=False)[2][2]
    normal = normal if normal[2] < 0 else -normal          # towards the cameras
    height = (xyz - centre) @ normal
    x, y = xyz[:, 0], xyz[:, 1]
    margin = 20
    span = max(np.ptp(x), np.ptp(y), 1e-9)
    scale = (min(w, h - 30) - 2 * margin) / span
    px = (margin + (x - x.min()) * scale).astype(int)
    py = (margin + (y - y.min()) * scale).astype(int)
    lim = max(float(np.abs(height).max()), 1e-9)
    t = np.clip(0.5 + 0.5 * height / lim, 0, 1)
    colours = cv2.applyColorMap((255 * t).astype(np.uint8).reshape(-1, 1), cv2.COLORMAP_JET)
    for i in range(len(px)):     # drawing only
        cv2.circle(img, (int(px[i]), int(py[i])), 4, tuple(int(c) for c in colours[i, 0]), -1)
    cv2.putText(img, f"{len(pts)} points; height vs plane {-1e3 * lim:+.3f}..{1e3 * lim:+.3f}"
                f" mm (red = towards cameras)", (10, h - 10), cv2.FONT_HERSHEY_PLAIN, 1.0,
                (0, 0, 0), 1, cv2.LINE_AA)
    return img


# ---------------------------------------------------------------------- pad-frame maps
# Pad-frame pictures seen from the touching object's side: x to the right, y up, z towards
# the viewer.  OpenCV and numpy only.

_FONT = 0  # cv2.FONT_HERSHEY_SIMPLEX
_GREY_BGR = (128, 128, 128)


def _nice_step(span: float, ticks: int = 6) -> float:
    raw = span / max(ticks, 1)
    mag = 10.0 ** math.floor(math.log10(raw)) if raw > 0 else 1.0
    return next(m * mag for m in (1, 2, 5, 10) if m * mag >= raw)


class _Plot:
    """A canvas with one data rectangle (mm, y up), its axes and a colour bar."""

    def __init__(self, extent_mm: tuple[float, float, float, float], title: str,
                 plot_px: int = 560) -> None:
        self.cv2 = cv2
        x0, x1, y0, y1 = extent_mm
        self.extent = extent_mm
        self.scale = plot_px / max(x1 - x0, y1 - y0)          # px per mm
        self.w, self.h = int(round((x1 - x0) * self.scale)), int(round((y1 - y0) * self.scale))
        self.left, self.top = 70, 60
        self.img = np.full((self.top + self.h + 75, self.left + self.w + 150, 3), 255, np.uint8)
        cv2.putText(self.img, title, (10, 25), _FONT, 0.55, (0, 0, 0), 1, cv2.LINE_AA)

    def px(self, x_mm: np.ndarray | float, y_mm: np.ndarray | float) -> tuple[Any, Any]:
        """Pixel (u, v) of pad-frame (x, y) in mm."""
        x0, _, _, y1 = self.extent
        return (self.left + (np.asarray(x_mm) - x0) * self.scale,
                self.top + (y1 - np.asarray(y_mm)) * self.scale)

    def paste(self, bgr: np.ndarray) -> None:
        """An image covering the data rectangle (row 0 = top = largest y)."""
        self.img[self.top:self.top + self.h, self.left:self.left + self.w] = self.cv2.resize(
            bgr, (self.w, self.h), interpolation=self.cv2.INTER_NEAREST)

    def axes(self) -> None:
        cv2, img = self.cv2, self.img
        x0, x1, y0, y1 = self.extent
        cv2.rectangle(img, (self.left, self.top), (self.left + self.w, self.top + self.h),
                      (0, 0, 0), 1)
        step = _nice_step(max(x1 - x0, y1 - y0), 8)
        for t in np.arange(math.ceil(x0 / step) * step, x1 + 1e-9, step):
            u = int(round(float(self.px(t, y0)[0])))
            cv2.line(img, (u, self.top + self.h), (u, self.top + self.h + 5), (0, 0, 0), 1)
            cv2.putText(img, f"{t:g}", (u - 10, self.top + self.h + 20), _FONT, 0.4, (0, 0, 0),
                        1, cv2.LINE_AA)
        for t in np.arange(math.ceil(y0 / step) * step, y1 + 1e-9, step):
            v = int(round(float(self.px(x0, t)[1])))
            cv2.line(img, (self.left - 5, v), (self.left, v), (0, 0, 0), 1)
            cv2.putText(img, f"{t:g}", (self.left - 35, v + 4), _FONT, 0.4, (0, 0, 0), 1,
                        cv2.LINE_AA)
        cv2.putText(img, "x (mm)", (self.left + self.w // 2 - 20, self.top + self.h + 42), _FONT,
                    0.45, (0, 0, 0), 1, cv2.LINE_AA)
        cv2.putText(img, "y (mm)", (5, self.top - 10), _FONT, 0.45, (0, 0, 0), 1, cv2.LINE_AA)

    def colour_bar(self, vmax: float, unit: str, colormap: int, nan_label: str = "") -> None:
        cv2, img = self.cv2, self.img
        u0, v0, bw = self.left + self.w + 25, self.top, 20
        ramp = np.linspace(255, 0, self.h).astype(np.uint8).reshape(-1, 1)
        bar = cv2.applyColorMap(np.repeat(ramp, bw, axis=1), colormap)
        img[v0:v0 + self.h, u0:u0 + bw] = bar
        cv2.rectangle(img, (u0, v0), (u0 + bw, v0 + self.h), (0, 0, 0), 1)
        step = _nice_step(vmax, 5)
        for t in np.arange(0.0, vmax + 1e-9, step):
            v = int(round(v0 + self.h * (1 - t / vmax)))
            cv2.line(img, (u0 + bw, v), (u0 + bw + 5, v), (0, 0, 0), 1)
            cv2.putText(img, f"{t:g}", (u0 + bw + 8, v + 4), _FONT, 0.4, (0, 0, 0), 1,
                        cv2.LINE_AA)
        cv2.putText(img, unit, (u0 - 5, v0 - 10), _FONT, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
        if nan_label:
            v = v0 + self.h + 20
            cv2.rectangle(img, (u0, v - 12), (u0 + bw, v + 2), _GREY_BGR, -1)
            cv2.putText(img, nan_label, (u0 + bw + 6, v), _FONT, 0.4, (0, 0, 0), 1, cv2.LINE_AA)


def _ceiling(top: float) -> float:
    """A round colour-bar maximum just above ``top`` (> 0)."""
    if top <= 0:
        return 1.0
    step = _nice_step(top, 10)
    return math.ceil(top / step) * step


def _colours(values: np.ndarray, vmax: float, colormap: int) -> np.ndarray:
    t = np.clip(np.nan_to_num(values / vmax), 0.0, 1.0)
    return cv2.applyColorMap((255 * t).astype(np.uint8).reshape(-1, 1), colormap)[:, 0]


def _fill_cells(plot: _Plot, xy_mm: np.ndarray, half_mm: float, colours: np.ndarray) -> None:
    """Each cell a filled square of side 2 ``half_mm`` at its (x, y) mm, in its BGR colour."""
    for (x, y), c in zip(xy_mm, colours):                    # drawing only
        u0, v0 = plot.px(x - half_mm, y + half_mm)
        u1, v1 = plot.px(x + half_mm, y - half_mm)
        cv2.rectangle(plot.img, (int(round(float(u0))), int(round(float(v0)))),
                      (int(round(float(u1))), int(round(float(v1)))),
                      tuple(int(k) for k in c), -1)          # 1 px overlap: no seams


def render_pressure(field_points: np.ndarray, pitch: float, title: str = "") -> np.ndarray:
    """BGR picture of the per-cell pressure (kPa) with shear arrows, pad frame, axes in mm.

    ``field_points``: the ``field`` cloud as a structured array (x, y, dx, dy, row, col,
    fx, fy, fz).  Each cell is a square of one pitch at its rest position; its pressure is
    max(0, -fz) / pitch^2.  Arrows: the tangential force (fx, fy) of every other cell
    where it exceeds 5 % of the largest one; the cross is the pressure-weighted centroid.
    """
    rest = np.column_stack([field_points["x"] - field_points["dx"],
                            field_points["y"] - field_points["dy"]]).astype(np.float64) * 1e3
    fz = np.asarray(field_points["fz"], np.float64)
    ft = np.column_stack([field_points["fx"], field_points["fy"]]).astype(np.float64)
    p_kpa = np.maximum(-fz, 0.0) / pitch ** 2 / 1e3
    half = pitch * 1e3 / 2
    extent = (rest[:, 0].min() - half, rest[:, 0].max() + half,
              rest[:, 1].min() - half, rest[:, 1].max() + half) if len(rest) else (-1, 1, -1, 1)
    plot = _Plot(extent, title or "pressure per cell (kPa) and shear, pad frame")
    vmax = _ceiling(float(p_kpa.max(initial=0.0)))
    cmap = cv2.COLORMAP_VIRIDIS
    colours = _colours(p_kpa, vmax, cmap)
    _fill_cells(plot, rest, half, colours)
    mag = np.hypot(ft[:, 0], ft[:, 1])
    big = float(mag.max(initial=0.0))
    if big > 0:
        show = ((mag > 0.05 * big) & (field_points["row"] % 2 == 0)
                & (field_points["col"] % 2 == 0))
        length = 2.5 * pitch * 1e3 / big                     # mm per N: longest = 2.5 pitch
        for (x, y), f in zip(rest[show], ft[show]):
            a = plot.px(x, y)
            b = plot.px(x + f[0] * length, y + f[1] * length)
            cv2.arrowedLine(plot.img, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])),
                            (255, 255, 255), 1, cv2.LINE_AA, tipLength=0.3)
    total = float(np.maximum(-fz, 0.0).sum())
    if total > 0:
        cx, cy = (np.maximum(-fz, 0.0)[:, None] * rest).sum(axis=0) / total
        u, v = plot.px(cx, cy)
        cv2.drawMarker(plot.img, (int(u), int(v)), (0, 0, 255), cv2.MARKER_CROSS, 18, 2)
    plot.axes()
    plot.colour_bar(vmax, "kPa", cmap)
    cv2.putText(plot.img, f"arrows: shear per cell (longest {1e3 * big:.2f} mN = 2.5 pitch); "
                "red cross: centroid; seen from the object (z towards you)",
                (10, plot.img.shape[0] - 10), _FONT, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return plot.img


def render_cells(xy_mm: np.ndarray, values: np.ndarray, pitch_mm: float, title: str,
                 unit: str, vmax: float | None = None,
                 circle: tuple[float, float, float] | None = None,
                 colormap: int = cv2.COLORMAP_INFERNO) -> np.ndarray:
    """BGR picture of one value per cell (a square of one pitch at its rest position).

    Pad frame, axes in mm; NaN cells grey; ``vmax`` the colour bar's top (default: a round
    number above the largest value); ``circle`` (x, y, r) mm drawn in white (a contact).
    """
    xy = np.asarray(xy_mm, np.float64).reshape(-1, 2)
    v = np.asarray(values, np.float64).reshape(-1)
    half = pitch_mm / 2
    extent = ((xy[:, 0].min() - half, xy[:, 0].max() + half,
               xy[:, 1].min() - half, xy[:, 1].max() + half) if len(xy) else (-1, 1, -1, 1))
    plot = _Plot(extent, title, plot_px=420)
    top = _ceiling(float(np.nanmax(v, initial=0.0))) if vmax is None else vmax
    colours = _colours(v, top, colormap)
    colours[~np.isfinite(v)] = _GREY_BGR
    _fill_cells(plot, xy, half, colours)
    if circle is not None:
        (u, w), r = plot.px(circle[0], circle[1]), circle[2] * plot.scale
        cv2.circle(plot.img, (int(round(float(u))), int(round(float(w)))), int(round(r)),
                   (255, 255, 255), 1, cv2.LINE_AA)
    plot.axes()
    plot.colour_bar(top, unit, colormap, "none" if not np.all(np.isfinite(v)) else "")
    return plot.img


def render_depth(depth: np.ndarray, x0: float, y0: float, resolution: float,
                 title: str = "") -> np.ndarray:
    """BGR picture of a depth map (m of indentation; NaN grey), colour bar in um, axes in mm.

    Pixel (i, j) of ``depth`` lies at (x0 + j res, y0 + i res) in the pad frame (the
    ``depth`` topic's grid, docs/touch.md).
    """
    h, w = depth.shape
    half = resolution / 2
    x_lo, x_hi, y_lo, y_hi = (1e3 * v for v in (x0 - half, x0 + (w - 1) * resolution + half,
                                                y0 - half, y0 + (h - 1) * resolution + half))
    plot = _Plot((x_lo, x_hi, y_lo, y_hi), title or "depth map (um of indentation), pad frame")
    um = depth.astype(np.float64) * 1e6
    finite = np.isfinite(um)
    top = float(um[finite].max(initial=0.0)) if finite.any() else 0.0
    vmax = _ceiling(top)
    cmap = cv2.COLORMAP_INFERNO
    img = _colours(um.ravel(), vmax, cmap).reshape(h, w, 3)
    img[~finite] = _GREY_BGR
    plot.paste(img[::-1])                                      # row 0 = largest y
    plot.axes()
    plot.colour_bar(vmax, "um", cmap, "not decoded")
    cv2.putText(plot.img, f"max {top:.0f} um at the cells; seen from the object (z towards you)",
                (10, plot.img.shape[0] - 10), _FONT, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return plot.img
