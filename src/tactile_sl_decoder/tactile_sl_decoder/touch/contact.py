"""Contact state and depth map from per-cell forces and displacements (pad frame).

What a grasping stack reads: whether something touches (with hysteresis, so that noise
near the threshold does not chatter), where (pressure-weighted centroid), how much area
presses, how deep the pad is pushed in (between cells too), and the separate contact
regions with their own force, area and centroid.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from tactile_sl_common.settings import SettingsTable


@dataclass
class ContactParams:
    """Thresholds of the contact state."""

    force_on: float = 0.010
    """N: in_contact turns on above this normal force"""
    force_off: float = 0.005
    """N: in_contact turns off below this normal force (hysteresis; <= contact_force_on)"""
    area_fraction: float = 0.0
    """A cell counts into the area above this x its region's peak; 0 = the traction
    solver's choice for the elastomer."""
    core_fraction: float = 0.3
    """A region's centroid from its cells above this x its peak."""
    displacement_noise: float = 3e-6
    """m per axis: weighs the two centroid estimates."""
    map_centroid_sigma: float = 6e-5
    """m: uncertainty of the map's centroid (pitch / 8)."""
    depth_upsample: int = 4
    """Depth-map pixels per cell pitch."""

    def validate(self) -> "ContactParams":
        """Raise ValueError for values outside their ranges (:data:`CONTACT_SETTINGS`)."""
        CONTACT_SETTINGS.check(self, "contact_")
        if self.force_off > self.force_on:
            raise ValueError(f"contact_force_off ({self.force_off}) must not exceed "
                             f"contact_force_on ({self.force_on})")
        if not 0 <= self.core_fraction < 1:
            raise ValueError(f"core_fraction must be in [0, 1), got {self.core_fraction}")
        if self.displacement_noise <= 0 or self.map_centroid_sigma <= 0:
            raise ValueError("displacement_noise and map_centroid_sigma must be > 0")
        if not 0 <= self.area_fraction < 1:
            raise ValueError(f"area_fraction must be in [0, 1), got {self.area_fraction}")
        if not 1 <= self.depth_upsample <= 16:
            raise ValueError(f"depth_upsample must be in 1..16, got {self.depth_upsample}")
        return self


CONTACT_SETTINGS = SettingsTable(ContactParams, fields=("force_on", "force_off"),
                                 ranges={"force_on": (1e-4, 100.0), "force_off": (1e-4, 100.0)})
"""The decoder node's live ``contact_force_on`` and ``contact_force_off`` parameters."""


@dataclass
class ContactState:
    """The contract's Contact message, plus regions (all SI, pad frame)."""

    in_contact: bool = False
    area: float = 0.0
    centroid: tuple[float, float, float] = (0.0, 0.0, 0.0)
    max_depth: float = 0.0
    normal_force: float = 0.0
    shear_force: tuple[float, float, float] = (0.0, 0.0, 0.0)
    peak_pressure: float = 0.0
    cells_in_contact: int = 0
    region_force: list[float] = field(default_factory=list)
    region_area: list[float] = field(default_factory=list)
    region_centroid: list[tuple[float, float, float]] = field(default_factory=list)


_DR, _DC = (a.ravel() for a in np.mgrid[-1:2, -1:2])
# Least-squares operator of z = a + b x + c y + d x^2 + e y^2 + g x y on the full 3x3 stencil.
_STENCIL = np.linalg.pinv(np.column_stack([np.ones(9), _DC, _DR, _DC ** 2, _DR ** 2,
                                           _DC * _DR]).astype(float))


def max_indentation(indent: np.ndarray) -> float:
    """Largest indentation of a (rows, cols) grid (NaN = not decoded), between cells too.

    A quadratic z = a + b x + c y + d x^2 + e y^2 + g x y is fitted by least squares to the
    decoded cells of the 3x3 neighbourhood of the deepest cell; its stationary point gives
    the peak when it is a maximum within one cell (a spherical tip's surface is exactly such
    a paraboloid inside the contact).  Never less than the deepest decoded cell, never < 0.
    """
    flat = np.nan_to_num(indent, nan=-np.inf)
    i = int(np.argmax(flat))
    best = float(flat.flat[i])
    if not np.isfinite(best):
        return 0.0
    r0, c0 = divmod(i, indent.shape[1])
    r, c = r0 + _DR, c0 + _DC
    if r0 >= 1 and c0 >= 1 and r0 + 1 < indent.shape[0] and c0 + 1 < indent.shape[1]:
        z = indent[r, c]
        good = np.isfinite(z)
        if good.all():
            coef = _STENCIL @ z
        elif good.sum() >= 7:
            a = np.column_stack([np.ones(9), _DC, _DR, _DC ** 2, _DR ** 2, _DC * _DR])
            coef = np.linalg.lstsq(a[good].astype(float), z[good], rcond=None)[0]
        else:
            return max(best, 0.0)
        # a maximum: negative-definite Hessian [[2d, g], [g, 2e]]
        d2, e2, g = 2 * coef[3], 2 * coef[4], coef[5]
        det = d2 * e2 - g * g
        if d2 < 0 and det > 0:
            xs = (-coef[1] * e2 + coef[2] * g) / det
            ys = (-coef[2] * d2 + coef[1] * g) / det
            if abs(xs) <= 1.0 and abs(ys) <= 1.0:
                peak = float(coef[0] + coef[1] * xs + coef[2] * ys + coef[3] * xs * xs
                             + coef[4] * ys * ys + coef[5] * xs * ys)
                best = max(best, peak)
    return max(best, 0.0)


def contact_state(rest_xy: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                  forces: np.ndarray, wrench: np.ndarray, shape: tuple[int, int], pitch: float,
                  indent_grid: np.ndarray, was_in_contact: bool, params: ContactParams,
                  moment_noise: tuple[float, float] = (0.0, 0.0)) -> ContactState:
    """Contact state from per-cell forces (N) at rest positions (m) and the resultant.

    Normal and shear force come from the resultant.  The area and the regions come from
    the per-cell map: a cell counts into the area when it presses by more than
    ``area_fraction`` of the map's peak, and a region is a set of 8-connected pressing cells
    with at least one such cell (smaller ripples of the map are not contacts; the map
    is smooth over about a cell, so its low skirt lies outside the contact; the stage
    passes the fraction its traction solver calibrated for the elastomer, see
    :meth:`~tactile_sl_decoder.touch.traction.TractionSolver._area_fraction`).

    The centroid has two estimates: the resultant's, (M_y, -M_x) / P (exact for tractions
    at z = 0 since M = sum r x f, but its noise grows with the lever arms of the whole
    field: ``moment_noise`` is ||row|| of the M_x, M_y functionals, so the standard
    deviation is ``displacement_noise`` x that / P), and the map's (force-weighted region
    centroids, each from the region's cells above ``core_fraction`` of its peak: local,
    uncertain to about ``map_centroid_sigma``).  They are combined per axis by inverse
    variance (the minimum-variance unbiased combination of two independent estimates).
    """
    press = np.maximum(-forces[:, 2], 0.0)
    normal = max(-float(wrench[2]), 0.0)
    cell_area = pitch * pitch
    state = ContactState(normal_force=normal,
                         shear_force=(float(wrench[0]), float(wrench[1]), 0.0),
                         max_depth=max_indentation(indent_grid))
    threshold = params.force_off if was_in_contact else params.force_on
    state.in_contact = normal > threshold
    pressing = press > 0.0
    if normal <= 0.0 or not pressing.any():
        return state
    state.peak_pressure = float(press.max() / cell_area)
    grid = np.zeros(shape, np.uint8)
    grid[rows[pressing], cols[pressing]] = 1
    count, labels = cv2.connectedComponents(grid, connectivity=8)
    region = labels[rows, cols]
    regions = []
    level = params.area_fraction * float(press.max())
    for k in range(1, count):
        sel = pressing & (region == k)
        w = press[sel]
        inside = int((w > level).sum())
        if inside == 0:          # a ripple of the map, not a contact
            continue
        f = float(w.sum())
        core = np.where(w > params.core_fraction * w.max(), w, 0.0)
        c = (core[:, None] * rest_xy[sel]).sum(axis=0) / core.sum()
        regions.append((f, inside * cell_area, (float(c[0]), float(c[1]), 0.0), inside))
    regions.sort(key=lambda t: -t[0])
    state.region_force = [r[0] for r in regions]
    state.region_area = [r[1] for r in regions]
    state.region_centroid = [r[2] for r in regions]
    state.area = float(sum(state.region_area))
    state.cells_in_contact = int(sum(r[3] for r in regions))
    total = sum(state.region_force)
    from_map = np.array([sum(f * c[i] for f, c in zip(state.region_force,
                                                      state.region_centroid)) / total
                         for i in (0, 1)])
    from_wrench = np.array([float(wrench[4]) / normal, -float(wrench[3]) / normal])
    var_wrench = (params.displacement_noise * np.array([moment_noise[1], moment_noise[0]])
                  / normal) ** 2
    w_map = 1.0 / params.map_centroid_sigma ** 2
    w_wrench = 1.0 / np.maximum(var_wrench, 1e-30)
    cx, cy = (w_map * from_map + w_wrench * from_wrench) / (w_map + w_wrench)
    state.centroid = (float(cx), float(cy), 0.0)
    return state


@dataclass(frozen=True)
class DepthGrid:
    """Where the depth map's pixels lie: pixel (i, j) is at (x0 + j res, y0 + i res, 0)."""

    x0: float
    y0: float
    resolution: float
    width: int
    height: int


def depth_grid(shape: tuple[int, int], pitch: float, upsample: int,
               mirrored: bool = False) -> DepthGrid:
    """The depth map covers the pattern's cell centres, ``upsample`` pixels per pitch."""
    rows, cols = shape
    res = pitch / upsample
    width = (cols - 1) * upsample + 1
    height = (rows - 1) * upsample + 1
    return DepthGrid(-(cols - 1) / 2.0 * pitch, -(rows - 1) / 2.0 * pitch, res, width, height)


class DepthMapper:
    """Indentation (m, > 0 pressed in) on the depth grid, bilinear between cell centres.

    ``indent`` is the (rows, cols) cell grid, NaN where a cell was not decoded; a pixel is
    NaN when any cell it interpolates between (with a non-zero weight) is missing, so cell
    centres keep their value next to a gap.  With ``mirrored`` the columns are flipped so
    that image x always runs along the pad frame's x.  The sampling maps are built once
    (cv2.remap: bilinear weights in 1/32 steps, exact for 1, 2, 4, 8, 16 pixels per pitch).
    """

    def __init__(self, shape: tuple[int, int], upsample: int, mirrored: bool = False) -> None:
        rows, cols = shape
        self.mirrored = bool(mirrored)
        ys = np.arange((rows - 1) * upsample + 1, dtype=np.float32) / upsample
        xs = np.arange((cols - 1) * upsample + 1, dtype=np.float32) / upsample
        self._map_x, self._map_y = np.meshgrid(xs, ys)

    def __call__(self, indent: np.ndarray) -> np.ndarray:
        grid = indent[:, ::-1] if self.mirrored else indent
        valid = np.isfinite(grid)
        both = np.dstack([np.where(valid, grid, 0.0), valid]).astype(np.float32)
        out = cv2.remap(both, self._map_x, self._map_y, cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)
        depth = out[..., 0].copy()
        depth[out[..., 1] < 1.0 - 1e-6] = np.nan
        return depth


def depth_map(indent: np.ndarray, upsample: int, mirrored: bool = False) -> np.ndarray:
    """One-off :class:`DepthMapper` call (tests, tools)."""
    return DepthMapper(indent.shape, upsample, mirrored)(indent)
