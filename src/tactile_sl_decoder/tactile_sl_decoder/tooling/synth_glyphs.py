"""Synthetic glyph-grid images with exact ground truth, for tests, benchmarks and augmentation.

A lightweight 2-D stand-in for the ray-cast simulator: the shipped glyph shapes
(:mod:`tactile_sl_decoder.pattern.shapes`) drawn on a grid seen through a smooth warp
(scale, shear, rotation and a radial bulge like an indentation), then blurred, unevenly lit
and noisy. The warp maps pixels to the artwork plane, so rendering is one vectorised pass;
ground-truth pixel centres come from inverting it by fixed-point iteration.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

from tactile_sl_decoder.pattern.shapes import glyph

DEFAULT_PRIMITIVES = ("line", "circle", "triangle")


@dataclass
class SynthImage:
    """A rendered image and the truth about every glyph whose centre lies inside it."""

    gray: np.ndarray
    u: np.ndarray
    v: np.ndarray
    label: np.ndarray
    row: np.ndarray
    col: np.ndarray
    spacing_px: float


@dataclass
class Warp:
    """Pixel -> artwork (cell units) map: affine plus a Gaussian radial bulge."""

    matrix: np.ndarray  # 2x3, pixel -> cell units
    bulge_centre: tuple[float, float] = (320.0, 240.0)  # pixels
    bulge_sigma: float = 80.0  # pixels
    bulge_gain: float = 0.0  # fraction: >0 magnifies the centre (pad pushed towards camera)

    def to_cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Artwork coordinates (col, row in cell units) of pixel (x, y)."""
        dx = x - self.bulge_centre[0]
        dy = y - self.bulge_centre[1]
        g = 1.0 - self.bulge_gain * np.exp(-(dx * dx + dy * dy) / (2 * self.bulge_sigma ** 2))
        xs = self.bulge_centre[0] + dx * g
        ys = self.bulge_centre[1] + dy * g
        m = self.matrix
        return m[0, 0] * xs + m[0, 1] * ys + m[0, 2], m[1, 0] * xs + m[1, 1] * ys + m[1, 2]

    def to_pixels(self, c: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel of artwork point (c, r), inverting :meth:`to_cells` by fixed-point steps."""
        inv = cv2.invertAffineTransform(self.matrix)
        x = inv[0, 0] * c + inv[0, 1] * r + inv[0, 2]
        y = inv[1, 0] * c + inv[1, 1] * r + inv[1, 2]
        for _ in range(60):
            cc, rr = self.to_cells(x, y)
            ex, ey = c - cc, r - rr
            x = x + inv[0, 0] * ex + inv[0, 1] * ey
            y = y + inv[1, 0] * ex + inv[1, 1] * ey
        return x, y


def random_warp(rng: np.random.Generator, spacing: float, shape: tuple[int, int],
                strength: float = 1.0) -> Warp:
    """A plausible view of the pad: spacing +-, anisotropy, shear, small rotation, bulge."""
    h, w = shape
    sx = spacing * (1 + strength * rng.uniform(-0.08, 0.08))
    sy = spacing * (1 + strength * rng.uniform(-0.08, 0.08))
    rot = strength * rng.uniform(-0.06, 0.06)
    shear = strength * rng.uniform(-0.05, 0.05)
    a = np.array([[sx, shear * sx], [0.0, sy]]) @ np.array(
        [[np.cos(rot), -np.sin(rot)], [np.sin(rot), np.cos(rot)]])
    inv = np.linalg.inv(a)
    off = rng.uniform(0, 1, 2)
    matrix = np.hstack([inv, (off - inv @ np.array([w / 2, h / 2]))[:, None]])
    return Warp(matrix, (rng.uniform(0.3, 0.7) * w, rng.uniform(0.3, 0.7) * h),
                rng.uniform(50, 160), strength * rng.uniform(-0.25, 0.3))


def _subpixel_grid(shape: tuple[int, int], supersample: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates of ``supersample`` x ``supersample`` samples per pixel (x, y grids)."""
    h, w = shape
    off = (np.arange(supersample) + 0.5) / supersample - 0.5
    ys = (np.arange(h)[:, None] + off[None, :]).reshape(-1)
    xs = (np.arange(w)[:, None] + off[None, :]).reshape(-1)
    return np.meshgrid(xs, ys)


def render(values: np.ndarray, warp: Warp, shape: tuple[int, int] = (480, 640), *,
           primitives: tuple[str, ...] = DEFAULT_PRIMITIVES, supersample: int = 3,
           glyph_scale: float = 1.0, ink: float = 40.0, paper: float = 200.0) -> np.ndarray:
    """Ink coverage (float32, 0..1) of the glyph array ``values`` seen through ``warp``."""
    h, w = shape
    s = supersample
    gx, gy = _subpixel_grid(shape, s)
    c, r = warp.to_cells(gx, gy)
    ci = np.rint(c).astype(np.int64)
    ri = np.rint(r).astype(np.int64)
    rows, cols = values.shape
    valid = (ri >= 0) & (ri < rows) & (ci >= 0) & (ci < cols)
    val = np.where(valid, values[np.clip(ri, 0, rows - 1), np.clip(ci, 0, cols - 1)], 255)
    lx = (c - ci) / glyph_scale
    ly = (r - ri) / glyph_scale
    cover = np.zeros(gx.shape, bool)
    for k, name in enumerate(primitives):  # one vectorised test per primitive, not per glyph
        sel = val == k
        cover[sel] = glyph(name).inside(lx[sel], ly[sel])
    return cover.reshape(h, s, w, s).mean(axis=(1, 3)).astype(np.float32)


def finish(cover: np.ndarray, rng: np.random.Generator, *, blur: float = 0.8,
           noise: float = 3.0, gradient: float = 0.3, ink: float = 40.0,
           paper: float = 200.0) -> np.ndarray:
    """Grey image from coverage: optical blur, uneven illumination, sensor noise."""
    h, w = cover.shape
    img: np.ndarray = paper + (ink - paper) * cover
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    ang = rng.uniform(0, 2 * np.pi)
    ramp = ((xx - w / 2) * np.cos(ang) + (yy - h / 2) * np.sin(ang)) / max(h, w)
    vignette = ((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / (w * w / 4 + h * h / 4)
    img = img * (1 + gradient * ramp) * (1 - 0.5 * gradient * vignette)
    img = img + rng.normal(0, noise, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def synth_image(rng: np.random.Generator, *, spacing: float = 17.0,
                shape: tuple[int, int] = (480, 640), warp_strength: float = 1.0,
                blur: float | None = None, noise: float | None = None,
                gradient: float | None = None, values: np.ndarray | None = None,
                primitives: tuple[str, ...] = DEFAULT_PRIMITIVES) -> SynthImage:
    """A random glyph-grid image and its ground truth (glyphs fully inside the image)."""
    h, w = shape
    if values is None:
        n = int(max(h, w) / spacing * 1.6) + 4
        values = rng.integers(0, len(primitives), (n, n)).astype(np.uint8)
    warp = random_warp(rng, spacing, shape, warp_strength)
    warp.matrix[:, 2] += (np.array(values.shape[::-1]) - 1) / 2.0  # image centre -> array centre
    blur = rng.uniform(0.5, 1.4) if blur is None else blur
    noise = rng.uniform(1.0, 6.0) if noise is None else noise
    gradient = rng.uniform(0.0, 0.6) if gradient is None else gradient
    cover = render(values, warp, shape, primitives=primitives)
    gray = finish(cover, rng, blur=blur, noise=noise, gradient=gradient,
                  ink=rng.uniform(20, 70), paper=rng.uniform(170, 230))
    rr, cc = np.mgrid[0:values.shape[0], 0:values.shape[1]]
    x, y = warp.to_pixels(cc.reshape(-1).astype(float), rr.reshape(-1).astype(float))
    margin = 0.5 * spacing
    inside = (x >= margin) & (x <= w - 1 - margin) & (y >= margin) & (y <= h - 1 - margin)
    return SynthImage(gray, x[inside].astype(np.float32), y[inside].astype(np.float32),
                      values.reshape(-1)[inside], rr.reshape(-1)[inside],
                      cc.reshape(-1)[inside], float(spacing))


def render_at(centres: np.ndarray, values: np.ndarray, pitch_px: float,
              shape: tuple[int, int] = (480, 640), *,
              primitives: tuple[str, ...] = DEFAULT_PRIMITIVES,
              supersample: int = 3) -> np.ndarray:
    """Ink coverage of glyphs drawn at arbitrary pixel centres (N, 2), e.g. touching ones.

    Each sample is tested against its nearest centre's glyph, so overlapping glyphs meet
    along the line between them and stay connected.
    """
    h, w = shape
    s = supersample
    gx, gy = _subpixel_grid(shape, s)
    centres = np.asarray(centres, np.float64).reshape(-1, 2)
    dist, idx = cKDTree(centres).query(np.column_stack((gx.reshape(-1), gy.reshape(-1))))
    lx = (gx.reshape(-1) - centres[idx, 0]) / pitch_px
    ly = (gy.reshape(-1) - centres[idx, 1]) / pitch_px
    val = np.asarray(values)[idx]
    near = dist < pitch_px
    cover = np.zeros(gx.size, bool)
    for k, name in enumerate(primitives):
        sel = near & (val == k)
        cover[sel] = glyph(name).inside(lx[sel], ly[sel])
    return cover.reshape(h, s, w, s).mean(axis=(1, 3)).astype(np.float32)
