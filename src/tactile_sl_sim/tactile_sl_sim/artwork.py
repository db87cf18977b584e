"""The printed artwork the simulator textures the pad with, and stand-in drawings.

The artwork PNG (ink dark on white) and its YAML sidecar are produced by the pattern encoder
(``tactile-sl pattern render``); the sidecar maps artwork pixels to cells: ``cell00_px`` is
the centre of cell (0, 0) (x right, y down), cells step by ``pitch_px``, and the glyph ink
centroid of every cell is on its centre. A ``mirrored: true`` artwork is drawn mirrored
(columns run right to left in the PNG).
"""
from __future__ import annotations

import os
import pathlib
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import yaml

try:  # the installed artwork; from a source tree without ROS, the file beside the package
    from ament_index_python.packages import get_package_share_directory
except ImportError:  # pragma: no cover - without a ROS install
    get_package_share_directory = None  # type: ignore[assignment]  # checked where used

WORK_PITCH_PX = 40.0  # texture resolution the renderer resamples the artwork to (px per cell)


class ArtworkError(ValueError):
    """An artwork PNG or sidecar that is missing or inconsistent."""


def default_artwork_path() -> pathlib.Path:
    """The artwork installed with the package (share/tactile_sl_sim/artwork/pattern.png)."""
    try:
        if get_package_share_directory is None:
            raise LookupError("ament_index_python is not installed")
        share = pathlib.Path(get_package_share_directory("tactile_sl_sim"))
        return share / "artwork" / "pattern.png"
    except Exception:  # not installed: fall back to the source tree
        return pathlib.Path(__file__).resolve().parents[1] / "artwork" / "pattern.png"


@dataclass
class Artwork:
    """Albedo texture (1 = white pad, 0 = ink) resampled to WORK_PITCH_PX, with cell mapping."""

    albedo: np.ndarray  # float32 (H, W) in [0, 1]
    cell00_px: tuple[float, float]
    pitch_px: float
    pitch_m: float
    rows: int
    cols: int
    mirrored: bool = False
    source: str = "<memory>"

    def cell_to_pixel(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Texture pixel (x, y) of continuous cell coordinates (row, col)."""
        sx = -1.0 if self.mirrored else 1.0
        x = self.cell00_px[0] + sx * np.asarray(cols, dtype=np.float64) * self.pitch_px
        y = self.cell00_px[1] + np.asarray(rows, dtype=np.float64) * self.pitch_px
        return np.stack([x, y], axis=-1)


def _resample(albedo: np.ndarray, cell00: tuple[float, float], pitch_px: float,
              target: float) -> tuple[np.ndarray, tuple[float, float], float]:
    """Area-resample the texture to ~target px per cell (anti-aliased minification)."""
    if pitch_px <= target * 1.05:
        return albedo, cell00, pitch_px
    scale = target / pitch_px
    h, w = albedo.shape
    nw, nh = max(1, round(w * scale)), max(1, round(h * scale))
    sx, sy = nw / w, nh / h
    out = cv2.resize(albedo, (nw, nh), interpolation=cv2.INTER_AREA)
    # pixel centres: x_new + 0.5 = (x_old + 0.5) * s
    c = ((cell00[0] + 0.5) * sx - 0.5, (cell00[1] + 0.5) * sy - 0.5)
    return out, c, pitch_px * sx


def load_artwork(path: str | os.PathLike | None = None,
                 work_pitch_px: float = WORK_PITCH_PX) -> Artwork:
    """Load artwork PNG + ``.png.yaml`` sidecar; clear errors for missing or bad files."""
    p = pathlib.Path(path) if path else default_artwork_path()
    side = p.with_name(p.name + ".yaml")
    if not p.is_file():
        raise ArtworkError(f"{p}: no artwork PNG (render one with `tactile-sl pattern render "
                           f"PATTERN.yaml --png {p}` or pass another artwork path)")
    if not side.is_file():
        raise ArtworkError(f"{side}: the artwork's YAML sidecar is missing")
    try:
        meta = yaml.safe_load(side.read_text())
    except yaml.YAMLError as exc:
        raise ArtworkError(f"{side}: not valid YAML ({exc})") from exc
    if not isinstance(meta, dict):
        raise ArtworkError(f"{side}: expected a mapping")
    missing = [k for k in ("cell00_px", "pitch_px", "pitch_m", "rows", "cols") if k not in meta]
    if missing:
        raise ArtworkError(f"{side}: missing key(s) {', '.join(missing)}")
    image = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ArtworkError(f"{p}: not a readable image")
    if image.ndim == 3 and image.shape[2] == 4:  # transparent background counts as white
        alpha = image[:, :, 3:4].astype(np.float32) / 255.0
        image = (image[:, :, :3] * alpha + 255 * (1 - alpha)).astype(np.uint8)
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.dtype != np.uint8:
        image = (image.astype(np.float64) / np.iinfo(image.dtype).max * 255).astype(np.uint8)
    try:
        cell00 = (float(meta["cell00_px"][0]), float(meta["cell00_px"][1]))
        pitch_px, pitch_m = float(meta["pitch_px"]), float(meta["pitch_m"])
        rows, cols = int(meta["rows"]), int(meta["cols"])
    except (TypeError, ValueError, IndexError) as exc:
        raise ArtworkError(f"{side}: malformed values ({exc})") from exc
    if pitch_px <= 0 or pitch_m <= 0 or rows <= 0 or cols <= 0:
        raise ArtworkError(f"{side}: pitch, rows and cols must be positive")
    if not 1e-5 <= pitch_m <= 0.01:
        raise ArtworkError(f"{side}: pitch_m = {pitch_m} is not in metres "
                           "(expected about 0.0005)")
    albedo = image.astype(np.float32) / 255.0
    albedo, cell00, pitch_px = _resample(albedo, cell00, pitch_px, work_pitch_px)
    return Artwork(albedo, cell00, pitch_px, pitch_m, rows, cols,
                   bool(meta.get("mirrored", False)), str(p))


# --------------------------------------------------------------------------- stand-ins


def _glyph_mask(value: int, size: int, supersample: int = 4) -> np.ndarray:
    """Binary ink mask of one glyph (line, circle, triangle, ...) centred by ink centroid."""
    n = size * supersample
    canvas = np.zeros((n, n), np.uint8)
    c = n / 2.0
    r = 0.30 * n
    t = max(1, int(round(0.09 * n)))
    kind = value % 3
    if kind == 0:  # vertical bar (line)
        cv2.rectangle(canvas, (int(c - t / 2), int(c - r)), (int(c + t / 2), int(c + r)), 255, -1)
    elif kind == 1:  # ring (circle)
        cv2.circle(canvas, (int(c), int(c)), int(r * 0.85), 255, t)
    else:  # filled triangle
        pts = np.array([[c, c - r], [c - r * 0.95, c + r * 0.7], [c + r * 0.95, c + r * 0.7]])
        cv2.fillPoly(canvas, [np.round(pts).astype(np.int32)], 255)
    if value >= 3:  # larger alphabets: add a dot so shapes stay distinct
        cv2.circle(canvas, (int(c), int(c)), int(0.06 * n * (value // 3)), 0 if kind else 255, -1)
    ys, xs = np.nonzero(canvas)
    dy, dx = c - ys.mean() - 0.5, c - xs.mean() - 0.5  # move the ink centroid to the centre
    M = np.array([[1, 0, dx], [0, 1, dy]], dtype=np.float32)
    centred = cv2.warpAffine(canvas, M, (n, n), flags=cv2.INTER_LINEAR)
    return cv2.resize(centred, (size, size), interpolation=cv2.INTER_AREA)


def draw_artwork(values: np.ndarray, pitch_px: int = 40, pitch_m: float = 0.0005,
                 margin_cells: float = 1.0) -> tuple[np.ndarray, dict[str, Any]]:
    """A stand-in artwork (PNG pixels, sidecar dict) for tests and for missing artwork.

    Same conventions as the pattern encoder's artwork: one glyph per cell value, ink centroid
    on the cell centre, ``cell00_px`` the centre of cell (0, 0).
    """
    values = np.asarray(values)
    rows, cols = values.shape
    margin = int(round(margin_cells * pitch_px))
    h, w = rows * pitch_px + 2 * margin, cols * pitch_px + 2 * margin
    ink = np.zeros((h, w), np.float32)
    glyphs = {v: _glyph_mask(int(v), pitch_px).astype(np.float32) / 255.0
              for v in np.unique(values)}
    for r in range(rows):
        for c in range(cols):
            y0, x0 = margin + r * pitch_px, margin + c * pitch_px
            ink[y0:y0 + pitch_px, x0:x0 + pitch_px] = glyphs[values[r, c]]
    png = np.clip(255.0 * (1.0 - ink), 0, 255).astype(np.uint8)
    centre = margin + (pitch_px - 1) / 2.0
    meta = {"cell00_px": [centre, centre], "pitch_px": float(pitch_px), "pitch_m": pitch_m,
            "rows": rows, "cols": cols, "symbols": int(values.max()) + 1,
            "primitives": ["line", "circle", "triangle"][: int(values.max()) + 1],
            "values_meaning": "0=line 1=circle 2=triangle", "mirrored": False}
    return png, meta


def write_artwork(path: str | os.PathLike, values: np.ndarray, **kwargs: Any) -> pathlib.Path:
    """Draw a stand-in artwork and write PNG + sidecar (never to the shipped artwork path)."""
    p = pathlib.Path(path)
    png, meta = draw_artwork(values, **kwargs)
    p.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(p), png)
    p.with_name(p.name + ".yaml").write_text(yaml.safe_dump(meta, sort_keys=False))
    return p


def random_values(rows: int = 30, cols: int = 28, symbols: int = 3, seed: int = 0) -> np.ndarray:
    """Random glyph values (not an M-array: for rendering tests only)."""
    return np.random.default_rng(seed).integers(0, symbols, size=(rows, cols))


def checkerboard_albedo(u: np.ndarray, v: np.ndarray, square: float, cols: int,
                        rows: int) -> np.ndarray:
    """Albedo of a checkerboard with cols x rows squares and a one-square white margin.

    (u, v) are board coordinates in metres from the first inner corner; inner corners lie on
    integer multiples of ``square``.
    """
    iu = np.floor(u / square).astype(np.int64)
    iv = np.floor(v / square).astype(np.int64)
    inside = (iu >= -1) & (iu < cols - 1) & (iv >= -1) & (iv < rows - 1)
    black = ((iu + iv) % 2 == 0) & inside
    board = (iu >= -2) & (iu < cols) & (iv >= -2) & (iv < rows)
    out = np.where(board, 0.95, 0.45).astype(np.float32)
    out[black] = 0.05
    return out
