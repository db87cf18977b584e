"""Contact mechanics of the elastomer pad: smooth displacement fields under indenters.

Each indenter has a core (a point for a sphere, a segment for a cylinder lying on the pad, an
infinite line for an edge, a disc for a flat punch) and the surface displacement depends on the
distance r to that core:

* curved indenters (sphere, cylinder, rounded edge of radius R pressed by depth d) follow the
  Hertz half-space solution with contact radius a = sqrt(R d): inside the contact the surface
  conforms to the indenter (w = d - r^2 / 2R), outside it relaxes as
  w = d/pi [(2 - r^2/a^2) asin(a/r) + sqrt(r^2/a^2 - 1)] (continuous slope at r = a);
* a flat punch of radius a follows Boussinesq's rigid punch, w = d inside and
  w = 2d/pi asin(a/r) outside, smoothed by the punch's edge fillet;
* the pad is a layer of finite thickness on a rigid window, so far-field displacements decay:
  the outside solution is windowed by exp(-((r - a) / thickness)^2);
* lateral displacement: the radial Hertz term for a compressible elastomer (``stretch``, from
  Poisson's ratio) and tangential traction (``shear`` vector, sticking in the contact and
  decaying with the normal profile), which is what sliding and shear sequences show.

Displacements of several contacts superpose (linear elasticity). The field is tabulated on a
fine grid over the pad; that tabulated surface (bilinear between nodes) is the ground truth
surface: rendering and ground truth both sample it.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from tactile_sl_common.elasticity import surface_displacement
from tactile_sl_sim.loads import LoadContact, is_load, load_traction

KINDS = ("sphere", "cylinder", "edge", "flat")


def stretch_from_poisson(nu: float) -> float:
    """Hertz radial surface displacement at the contact edge over depth, for Poisson ratio nu."""
    return float(2.0 * (1.0 - 2.0 * nu) / (3.0 * np.pi * (1.0 - nu)))


@dataclass
class PadParams:
    """Elastomer layer properties."""

    thickness: float = 0.002  # decay length of the far field (layer thickness), metres
    poisson: float = 0.45
    stretch_scale: float = 1.0  # 0 disables radial stretch, 1 = Hertz for `poisson`


@dataclass
class Contact:
    """One indenter's shape and its state in the current frame (metres, radians)."""

    kind: str = "sphere"
    radius: float = 0.005  # curvature radius (sphere/cylinder/edge) or punch radius (flat)
    length: float = 0.0  # straight length of a cylinder's axis
    angle: float = 0.0  # axis direction in the pad plane (cylinder, edge)
    fillet: float = 0.0001  # edge rounding of a flat punch (smoothing length)
    x: float = 0.0
    y: float = 0.0
    depth: float = 0.0
    shear: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown indenter {self.kind!r} (expected one of {', '.join(KINDS)})")
        if self.radius <= 0:
            raise ValueError(f"{self.kind} indenter radius must be positive, got {self.radius}")
        if self.depth < 0:
            raise ValueError(f"indentation depth must be >= 0, got {self.depth}")

    def contact_radius(self) -> float:
        if self.kind == "flat":
            return self.radius
        return float(np.sqrt(self.radius * self.depth))

    def half_length(self) -> float:
        if self.kind == "edge":
            return 1.0  # effectively infinite on a pad a few centimetres wide
        if self.kind == "cylinder":
            return self.length / 2.0
        return 0.0

    def core_distance(self, X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                    np.ndarray]:
        """Distance to the indenter core and the unit direction away from it."""
        c, s = np.cos(self.angle), np.sin(self.angle)
        dx, dy = X - self.x, Y - self.y
        along = dx * c + dy * s
        across = -dx * s + dy * c
        hl = self.half_length()
        off = along - np.clip(along, -hl, hl)
        r = np.hypot(off, across)
        safe = np.maximum(r, 1e-12)
        ux = (off * c - across * s) / safe
        uy = (off * s + across * c) / safe
        return r, ux, uy

    def displacement(self, X: np.ndarray, Y: np.ndarray, pad: PadParams) -> np.ndarray:
        """(..., 3) displacement (ux, uy, uz) at rest points; uz < 0 is towards the cameras."""
        out = np.zeros(np.shape(X) + (3,))
        d = self.depth
        if d <= 0:
            return out
        r, ex, ey = self.core_distance(X, Y)
        a = self.contact_radius()
        inside = r < a
        w = np.empty_like(r)
        rho = np.maximum(r / a, 1.0)
        window = np.where(inside, 1.0, np.exp(-((r - a) / pad.thickness) ** 2))
        if self.kind == "flat":
            w[:] = (2 * d / np.pi) * np.arcsin(1.0 / rho)
        else:
            w[:] = (d / np.pi) * ((2 - rho**2) * np.arcsin(1.0 / rho) + np.sqrt(rho**2 - 1))
            w[inside] = d - r[inside] ** 2 / (2 * self.radius)
        w *= window
        # Radial (Hertz, compressible) and tangential (shear traction) lateral displacement.
        k = stretch_from_poisson(pad.poisson) * pad.stretch_scale
        rin = np.minimum(r / a, 1.0)
        psi = np.where(inside, (1.0 - (1.0 - rin**2) ** 1.5) / np.maximum(rin, 1e-12),
                       1.0 / rho) * window
        ur = -k * d * psi
        profile = w / d
        out[..., 0] = ur * ex + self.shear[0] * profile
        out[..., 1] = ur * ey + self.shear[1] * profile
        out[..., 2] = -w
        return out

    def support(self, pad: PadParams) -> float:
        """Distance from the core beyond which the displacement is negligible (< 0.1 um)."""
        return self.contact_radius() + 2.6 * pad.thickness


@dataclass
class FieldGrid:
    """The pad's displacement field tabulated on a regular grid of rest positions."""

    x0: float = -0.0125
    y0: float = -0.0100
    spacing: float = 4e-5
    nx: int = 626
    ny: int = 501
    traction: np.ndarray | None = None  # (ny, nx, 3) Pa of the load contacts, None without
    data: np.ndarray = field(init=False)  # (ny, nx, 3) float64 displacement, zero until built
    slope: np.ndarray = field(init=False)  # (ny, nx, 2) dw/dX, dw/dY, zero until built

    def __post_init__(self) -> None:
        self.data = np.zeros((self.ny, self.nx, 3))
        self.slope = np.zeros((self.ny, self.nx, 2))
        self.active_box: tuple[float, float, float, float] | None = None
        self.active_index: tuple[int, int, int, int] | None = None
        self._table32: np.ndarray | None = None
        self._max: float | None = None

    @property
    def xs(self) -> np.ndarray:
        return self.x0 + self.spacing * np.arange(self.nx)

    @property
    def ys(self) -> np.ndarray:
        return self.y0 + self.spacing * np.arange(self.ny)

    @classmethod
    def build(cls, contacts: Sequence[Contact | LoadContact], pad: PadParams,
              **grid: Any) -> "FieldGrid":
        """Tabulate the superposed displacement of all contacts (indenters and loads)."""
        g = cls(**grid)
        xs, ys = g.xs, g.ys
        box = None
        idx = None  # union of the contacts' index boxes (iy0, iy1, ix0, ix1)
        loads = [c for c in contacts if is_load(c)]
        if loads:
            elastomers = {c.elastomer for c in loads}
            if len(elastomers) > 1:
                raise ValueError("load contacts of one frame must share one elastomer")
            g.traction = load_traction(loads, xs, ys, g.spacing)
            if np.any(g.traction):
                g.data += surface_displacement(elastomers.pop(), g.traction, g.spacing)
                box = (xs[0], ys[0], xs[-1], ys[-1])
                idx = (0, g.ny, 0, g.nx)
        for contact in contacts:
            if is_load(contact) or contact.depth <= 0:
                continue
            reach = contact.support(pad) + contact.half_length()
            ix0 = int(np.clip(np.floor((contact.x - reach - g.x0) / g.spacing), 0, g.nx))
            ix1 = int(np.clip(np.ceil((contact.x + reach - g.x0) / g.spacing) + 1, 0, g.nx))
            iy0 = int(np.clip(np.floor((contact.y - reach - g.y0) / g.spacing), 0, g.ny))
            iy1 = int(np.clip(np.ceil((contact.y + reach - g.y0) / g.spacing) + 1, 0, g.ny))
            if ix1 <= ix0 or iy1 <= iy0:
                continue
            X, Y = np.meshgrid(xs[ix0:ix1], ys[iy0:iy1])
            disp = contact.displacement(X, Y, pad)
            if contact.kind == "flat" and contact.fillet > 0:
                sigma = contact.fillet / g.spacing
                disp = cv2.GaussianBlur(disp, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)
            g.data[iy0:iy1, ix0:ix1] += disp
            b = (xs[ix0], ys[iy0], xs[ix1 - 1], ys[iy1 - 1])
            box = b if box is None else (min(box[0], b[0]), min(box[1], b[1]),
                                         max(box[2], b[2]), max(box[3], b[3]))
            i = (iy0, iy1, ix0, ix1)
            idx = i if idx is None else (min(idx[0], i[0]), max(idx[1], i[1]),
                                         min(idx[2], i[2]), max(idx[3], i[3]))
        g.active_box = box
        if idx is not None:  # the field is exactly zero outside the contacts' boxes
            iy0, iy1 = max(idx[0] - 1, 0), min(idx[1] + 1, g.ny)
            ix0, ix1 = max(idx[2] - 1, 0), min(idx[3] + 1, g.nx)
            idx = (iy0, iy1, ix0, ix1)
            if iy1 - iy0 >= 2 and ix1 - ix0 >= 2:
                gy, gx = np.gradient(g.data[iy0:iy1, ix0:ix1, 2], g.spacing)
                g.slope[iy0:iy1, ix0:ix1] = np.stack([gx, gy], axis=-1)
        g.active_index = idx
        return g

    @property
    def table_origin(self) -> tuple[float, float]:
        """Pad position of :attr:`table32`'s first node (the crop of the active region)."""
        if self.active_index is None:
            return self.x0, self.y0
        return (self.x0 + self.active_index[2] * self.spacing,
                self.y0 + self.active_index[0] * self.spacing)

    @property
    def table32(self) -> np.ndarray:
        """float32 ux, uy, uz, duz/dX, duz/dY over the active region (one rendering lookup).

        Zero outside it, as the field is; its first node is at :attr:`table_origin`.
        """
        if self._table32 is None:
            iy0, iy1, ix0, ix1 = self.active_index or (0, self.ny, 0, self.nx)
            self._table32 = np.ascontiguousarray(np.concatenate(
                [self.data[iy0:iy1, ix0:ix1], self.slope[iy0:iy1, ix0:ix1]], axis=2),
                dtype=np.float32)
        return self._table32

    def max_displacement(self) -> float:
        if self._max is None:
            self._max = float(np.abs(self.data).max()) if self.active_box else 0.0
        return self._max

    def sample(self, X: np.ndarray, Y: np.ndarray, which: str = "data") -> np.ndarray:
        """Exact float64 bilinear interpolation (zero outside the grid): ground truth."""
        table = self.data if which == "data" else self.slope
        X = np.asarray(X, dtype=np.float64)
        Y = np.asarray(Y, dtype=np.float64)
        fx = (X - self.x0) / self.spacing
        fy = (Y - self.y0) / self.spacing
        ix = np.floor(fx).astype(np.int64)
        iy = np.floor(fy).astype(np.int64)
        tx, ty = (fx - ix)[..., None], (fy - iy)[..., None]
        out = np.zeros(X.shape + (table.shape[2],))
        for dy, wy in ((0, 1 - ty), (1, ty)):
            for dx, wx in ((0, 1 - tx), (1, tx)):
                jx, jy = ix + dx, iy + dy
                ok = (jx >= 0) & (jx < self.nx) & (jy >= 0) & (jy < self.ny)
                vals = np.zeros(X.shape + (table.shape[2],))
                vals[ok] = table[jy[ok], jx[ok]]
                out += wx * wy * vals
        return out
