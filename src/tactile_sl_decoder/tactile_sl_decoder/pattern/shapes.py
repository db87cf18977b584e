"""Glyph geometry, defined once for the artwork, the simulator's artwork and the docs.

Every glyph is a filled shape in units of the pitch, centred so that the centroid of its
ink lies exactly at (0, 0) (the contract puts the ink centroid on the cell centre). All
glyphs have nearly the same ink area (:data:`INK_AREA` pitch^2) so that blob size alone
cannot tell them apart but also cannot reject one of them, and extents of 0.5-0.7 pitch
so that neighbours stay separated under blur. Coordinates: x right, y down.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

INK_AREA = 0.22
"""Target ink area of every glyph, in pitch^2."""

PRIMITIVE_ORDER: tuple[str, ...] = (
    "line", "circle", "triangle", "cross", "ring", "square", "diamond", "vline")
"""Primitive for value v when none is given: k=3 uses line, circle, triangle."""


def default_primitives(symbols: int) -> list[str]:
    """The primitive names for an alphabet of ``symbols`` values."""
    if not 1 <= symbols <= len(PRIMITIVE_ORDER):
        raise ValueError(f"no default glyph set for {symbols} symbols")
    return list(PRIMITIVE_ORDER[:symbols])


@dataclass(frozen=True)
class Glyph:
    """A filled shape: union of polygons and discs minus holes, in pitch units."""

    name: str
    polygons: tuple[tuple[tuple[float, float], ...], ...] = ()
    discs: tuple[tuple[float, float, float], ...] = ()   # (cx, cy, radius), filled
    holes: tuple[tuple[float, float, float], ...] = ()   # (cx, cy, radius), cut out

    def inside(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Boolean mask: which points (pitch units, relative to the cell centre) are ink."""
        mask = np.zeros(np.broadcast(x, y).shape, dtype=bool)
        for poly in self.polygons:
            mask |= _inside_convex(np.asarray(poly, dtype=np.float64), x, y)
        for cx, cy, radius in self.discs:
            mask |= (x - cx) ** 2 + (y - cy) ** 2 <= radius * radius
        for cx, cy, radius in self.holes:
            mask &= (x - cx) ** 2 + (y - cy) ** 2 > radius * radius
        return mask

    def extent(self) -> tuple[float, float]:
        """Width and height of the bounding box, in pitch units."""
        xs: list[float] = []
        ys: list[float] = []
        for poly in self.polygons:
            xs += [p[0] for p in poly]
            ys += [p[1] for p in poly]
        for cx, cy, radius in self.discs:
            xs += [cx - radius, cx + radius]
            ys += [cy - radius, cy + radius]
        return max(xs) - min(xs), max(ys) - min(ys)

    def svg_elements(self, cx_mm: float, cy_mm: float, pitch_mm: float) -> list[str]:
        """SVG elements (mm user units) drawing this glyph centred at (cx_mm, cy_mm)."""
        out: list[str] = []
        for poly in self.polygons:
            pts = " ".join(f"{cx_mm + x * pitch_mm:.5f},{cy_mm + y * pitch_mm:.5f}"
                           for x, y in poly)
            out.append(f'<polygon points="{pts}"/>')
        if self.holes:
            # ring: outer circle minus inner circle via even-odd path
            for (dx, dy, r_out), (_hx, _hy, r_in) in zip(self.discs, self.holes):
                out.append(_svg_annulus(cx_mm + dx * pitch_mm, cy_mm + dy * pitch_mm,
                                        r_out * pitch_mm, r_in * pitch_mm))
        else:
            for dx, dy, radius in self.discs:
                out.append(f'<circle cx="{cx_mm + dx * pitch_mm:.5f}" '
                           f'cy="{cy_mm + dy * pitch_mm:.5f}" r="{radius * pitch_mm:.5f}"/>')
        return out


def _svg_annulus(cx: float, cy: float, r_out: float, r_in: float) -> str:
    def circle(r: float) -> str:
        return (f"M {cx - r:.5f},{cy:.5f} a {r:.5f},{r:.5f} 0 1,0 {2 * r:.5f},0 "
                f"a {r:.5f},{r:.5f} 0 1,0 {-2 * r:.5f},0 Z")
    return f'<path fill-rule="evenodd" d="{circle(r_out)} {circle(r_in)}"/>'


def _inside_convex(poly: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Point-in-convex-polygon test (either winding), inclusive of edges."""
    sign_pos = np.ones(np.broadcast(x, y).shape, dtype=bool)
    sign_neg = sign_pos.copy()
    count = len(poly)
    for i in range(count):
        x0, y0 = poly[i]
        x1, y1 = poly[(i + 1) % count]
        cross = (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)
        sign_pos &= cross >= 0
        sign_neg &= cross <= 0
    return sign_pos | sign_neg


def _rect(w: float, h: float) -> tuple[tuple[float, float], ...]:
    return ((-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2))


def _build() -> dict[str, Glyph]:
    a = INK_AREA
    bar_len = 0.65
    bar_w = a / bar_len
    disc_r = math.sqrt(a / math.pi)
    # equilateral triangle pointing up, centroid at origin: centroid is h/3 above the base
    tri_side = math.sqrt(4 * a / math.sqrt(3))
    tri_h = tri_side * math.sqrt(3) / 2
    triangle = ((0.0, -2 * tri_h / 3), (tri_side / 2, tri_h / 3), (-tri_side / 2, tri_h / 3))
    # plus sign: two bars of length L, width t, area 2Lt - t^2 = a
    cross_len = 0.65
    cross_w = (2 * cross_len - math.sqrt(4 * cross_len ** 2 - 4 * a)) / 2
    ring_out = 0.32
    ring_in = math.sqrt(ring_out ** 2 - a / math.pi)
    sq = math.sqrt(a)
    dia = math.sqrt(2 * a) / 2
    glyphs = [
        Glyph("line", polygons=(_rect(bar_len, bar_w),)),
        Glyph("circle", discs=((0.0, 0.0, disc_r),)),
        Glyph("triangle", polygons=(triangle,)),
        Glyph("cross", polygons=(_rect(cross_len, cross_w), _rect(cross_w, cross_len))),
        Glyph("ring", discs=((0.0, 0.0, ring_out),), holes=((0.0, 0.0, ring_in),)),
        Glyph("square", polygons=(_rect(sq, sq),)),
        Glyph("diamond", polygons=(((0.0, -dia), (dia, 0.0), (0.0, dia), (-dia, 0.0)),)),
        Glyph("vline", polygons=(_rect(bar_w, bar_len),)),
    ]
    return {g.name: g for g in glyphs}


GLYPHS: dict[str, Glyph] = _build()
"""Every known glyph by primitive name."""


def glyph(name: str) -> Glyph:
    """Look up a glyph by primitive name, with a clear error for unknown names."""
    try:
        return GLYPHS[name]
    except KeyError:
        raise ValueError(f"unknown primitive {name!r}; known: {', '.join(GLYPHS)}") from None
