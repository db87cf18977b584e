"""Ray-casting renderer of the deformed pad, seen by the stereo rig, with ground truth.

Every image sample (``supersample`` x ``supersample`` per pixel, box-filtered down: anti-aliasing)
is a ray through the distorted pixel position, undistorted exactly (iterative inverse of the
plumb-bob model) and cached per camera. A ray first meets the undeformed pad plane Z = 0 at
rest position (X0, Y0). On the deformed pad the material point with rest position (X, Y) sits
at (X + ux, Y + uy, uz); the ray meets it where X = X0 + uz a - ux, Y = Y0 + uz b - uy (a, b the
ray's slopes dX/dZ, dY/dZ), solved by fixed-point iteration (a contraction: rays are steep and
the surface smooth), only for rays near a contact. The hit's rest position indexes the artwork
(texture mapping in material coordinates, so stretch and shear move the ink with the pad), and
the hit's position and normal give Lambertian shading from the sensor's light.

Nuisances (blur, noise, vignetting, uneven light, gamma, shadows, occluders, exposure) are
applied in the physical order: scene radiance, optics (occluders, blur, vignetting), sensor
(exposure, shot and read noise), then the camera's gamma and 8-bit quantisation.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import cv2
import numpy as np

from tactile_sl_sim.artwork import Artwork
from tactile_sl_sim.contact import Contact, FieldGrid, PadParams
from tactile_sl_sim.loads import LoadContact, TouchTruth, is_load, touch_truth
from tactile_sl_sim.optics import Camera, SimulatedCameraPair


@dataclass
class Nuisances:
    """Image nuisances; each one a parameter (defaults: a clean, realistic sensor)."""

    blur_sigma: float = 0.5  # optical blur, Gaussian sigma in pixels
    noise_sigma: float = 0.8  # read noise, grey levels (std)
    shot_noise: float = 0.02  # shot noise variance per grey level of signal
    vignetting: float = 0.2  # relative light loss in the image corners
    light: tuple[float, float, float] = (0.0, -0.006, -0.013)  # point light (pad frame, m)
    ambient: float = 0.35  # diffuse share of the illumination (fraction)
    illumination_gradient: tuple[float, float] = (0.0, 0.0)  # relative change per mm in X, Y
    gamma: float = 1.0  # output = linear ** (1 / gamma)
    exposure: float = 1.0  # gain on the signal
    exposure_jitter: float = 0.0  # per-frame relative std of the exposure
    white_level: float = 0.85  # grey level fraction of white paper at the centre, exposure 1
    paper: tuple[float, float, float] = (0.93, 0.92, 0.90)  # albedo, B G R
    ink: tuple[float, float, float] = (0.10, 0.09, 0.08)
    shadows: list[dict[str, float]] = field(default_factory=list)  # pad-space soft shadows
    occluders: list[dict[str, Any]] = field(default_factory=list)  # image-space dust/occluders
    # --- robustness nuisances (docs/camera.md "Nuisances of real sensors"); all off by default
    see_through: str = ""  # object seen between the glyphs in the contact area: "" (off),
    # dark | stripes | noise | text
    object_albedo: float = 0.15  # the touching object's mean albedo (paper 0.92, ink 0.09)
    object_contrast: float = 0.0  # albedo amplitude of its texture (dark features)
    object_scale: float = 4e-4  # texture feature size, m (stripe period, blob size, text height)
    object_depth_fraction: float = 0.5  # contact area: surface moved >= this share of the most
    jpeg_quality: int = 0  # MJPEG quality 1..100 of both streams; 0 = lossless
    defocus_px: float = 0.0  # defocus: pillbox (circle of confusion) radius, pixels
    motion_blur_px: float = 0.0  # motion blur: centred line kernel length, pixels
    motion_blur_angle_deg: float = 0.0  # its direction in the image (0 = along u)
    exposure_right: float = 1.0  # right camera's gain relative to the left one
    exposure_jitter_camera: float = 0.0  # per-frame relative std, independent per camera
    dropout: float = 0.0  # share of glyphs missing from the print (worn off)
    wear: float = 0.0  # share of glyphs partly worn (ink beyond a random chord lost)
    scratches: int = 0  # scratches across the print (ink removed along a line)
    bubbles: int = 0  # air bubbles under the print (faded disc, dark rim)
    dust: int = 0  # dark specks on each camera's optics, fixed in the image
    dust_radius_px: float = 2.5  # their mean radius, pixels
    dust_strength: float = 0.6  # their mean light loss at the centre (0..1)

    @classmethod
    def from_dict(cls, doc: dict[str, Any] | None) -> "Nuisances":
        """Nuisances from a YAML mapping; unknown keys are an error naming the known ones."""
        doc = dict(doc or {})
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(doc) - known)
        if unknown:
            raise ValueError(f"unknown nuisance parameter(s): {', '.join(unknown)} "
                             f"(known: {', '.join(sorted(known))})")
        for key in ("light", "illumination_gradient", "paper", "ink"):
            if key in doc:
                doc[key] = tuple(float(v) for v in doc[key])
        for key in ("shadows", "occluders"):
            if key in doc and not isinstance(doc[key], list):
                raise ValueError(f"{key} must be a list of mappings")
        out = cls(**doc)
        if out.gamma <= 0 or out.exposure < 0 or out.blur_sigma < 0 or out.noise_sigma < 0:
            raise ValueError("gamma must be > 0; exposure, blur_sigma and noise_sigma >= 0")
        out.check_robustness()
        return out

    def check_robustness(self) -> None:
        """Range checks of the robustness nuisances (ValueError naming the key)."""
        if self.see_through not in SEE_THROUGH:
            raise ValueError(f"see_through must be one of {', '.join(map(repr, SEE_THROUGH))}")
        checks = {
            "object_albedo": 0.0 <= self.object_albedo <= 1.0,
            "object_contrast": 0.0 <= self.object_contrast <= self.object_albedo + 1e-9,
            "object_scale": self.object_scale > 0,
            "object_depth_fraction": 0.0 < self.object_depth_fraction <= 1.0,
            "jpeg_quality": 0 <= int(self.jpeg_quality) <= 100,
            "defocus_px": self.defocus_px >= 0, "motion_blur_px": self.motion_blur_px >= 0,
            "exposure_right": self.exposure_right > 0,
            "exposure_jitter_camera": self.exposure_jitter_camera >= 0,
            "dropout": 0.0 <= self.dropout < 1.0, "wear": 0.0 <= self.wear <= 1.0,
            "scratches": int(self.scratches) >= 0, "bubbles": int(self.bubbles) >= 0,
            "dust": int(self.dust) >= 0, "dust_radius_px": self.dust_radius_px > 0,
            "dust_strength": 0.0 <= self.dust_strength <= 1.0}
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"nuisance(s) out of range: {', '.join(bad)} (see docs/camera.md)")

    @property
    def damages_print(self) -> bool:
        """Whether the printed artwork is altered (dropout, wear, scratches, bubbles)."""
        return bool(self.dropout or self.wear or self.scratches or self.bubbles)


SEE_THROUGH = ("", "dark", "stripes", "noise", "text")


@dataclass
class GroundTruth:
    """Every cell of the pattern: 3-D centre (left optical frame), projections, visibility."""

    rows: np.ndarray
    cols: np.ndarray
    xyz: np.ndarray  # (N, 3) metres, physical left camera optical frame
    world: np.ndarray  # (N, 3) pad frame
    px_left: np.ndarray  # (N, 2) exact distorted pixel positions
    px_right: np.ndarray
    visible: np.ndarray  # (N,) bool: visible in both images
    touch: TouchTruth | None = None  # force, contact and displacement truth (load scenes)
    damaged: np.ndarray | None = None  # (N,) bool: print damaged or dust over it (None: none)

    def visible_points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(xyz, rows, cols) of the glyphs visible in both images."""
        v = self.visible
        return self.xyz[v], self.rows[v], self.cols[v]


@dataclass
class StereoFrame:
    """One rendered stereo frame."""

    left: np.ndarray
    right: np.ndarray
    truth: GroundTruth
    field: FieldGrid


def _even_window(win: tuple[slice, slice], h: int, w: int) -> tuple[slice, slice]:
    """Grow a window by a pixel where needed so both sides are even (for 2x2 blocks)."""
    out = []
    for sl, size in zip(win, (h, w)):
        start, stop = int(sl.start), int(sl.stop)
        if (stop - start) % 2:
            if stop < size:
                stop += 1
            else:
                start -= 1
        out.append(slice(start, stop))
    return out[0], out[1]


class _RayTable:
    """Cached per-camera rays, at pixel centres (casting) and at supersamples (texture)."""

    def __init__(self, cam: Camera, ss: int) -> None:
        self.ss = ss
        self.shape = (cam.height, cam.width)
        self.shape_ss = (cam.height * ss, cam.width * ss)
        # pixel centres
        ys, xs = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
        d = cam.rays(np.stack([xs, ys], axis=-1).reshape(-1, 2))
        self.a = d[:, 0].reshape(self.shape).astype(np.float32)
        self.b = d[:, 1].reshape(self.shape).astype(np.float32)
        self.X0 = (cam.C[0] - cam.C[2] * d[:, 0]).reshape(self.shape).astype(np.float32)
        self.Y0 = (cam.C[1] - cam.C[2] * d[:, 1]).reshape(self.shape).astype(np.float32)
        # supersamples at (i + 0.5) / ss - 0.5 pixel units (cv2.resize's alignment): rays
        # interpolated bilinearly between exactly undistorted rays on a grid one pixel wider
        # than the image (the undistortion map is smooth: error < 1e-4 px).
        if ss == 1:
            self.a_ss, self.b_ss, self.X0_ss, self.Y0_ss = self.a, self.b, self.X0, self.Y0
            return
        ys, xs = np.mgrid[-1:cam.height + 1, -1:cam.width + 1].astype(np.float64)
        d = cam.rays(np.stack([xs, ys], axis=-1).reshape(-1, 2))
        ext = (cam.height + 2, cam.width + 2)
        da, db = d[:, 0].reshape(ext), d[:, 1].reshape(ext)
        a_ss = np.empty(self.shape_ss)
        b_ss = np.empty(self.shape_ss)
        h, w = self.shape
        for k in range(ss):
            fy = (k + 0.5) / ss - 0.5  # offset from the pixel centre, in pixels
            iy, ty = (0, 1 + fy) if fy < 0 else (1, fy)
            for m in range(ss):
                fx = (m + 0.5) / ss - 0.5
                ix, tx = (0, 1 + fx) if fx < 0 else (1, fx)
                for src, dst in ((da, a_ss), (db, b_ss)):
                    dst[k::ss, m::ss] = (
                        (1 - ty) * ((1 - tx) * src[iy:iy + h, ix:ix + w]
                                    + tx * src[iy:iy + h, ix + 1:ix + 1 + w])
                        + ty * ((1 - tx) * src[iy + 1:iy + 1 + h, ix:ix + w]
                                + tx * src[iy + 1:iy + 1 + h, ix + 1:ix + 1 + w]))
        self.a_ss = a_ss.astype(np.float32)
        self.b_ss = b_ss.astype(np.float32)
        self.X0_ss = (cam.C[0] - cam.C[2] * a_ss).astype(np.float32)
        self.Y0_ss = (cam.C[1] - cam.C[2] * b_ss).astype(np.float32)


def _pillbox(radius: float) -> np.ndarray:
    """Normalised disc kernel (circle of confusion) with anti-aliased edge, 8x supersampled."""
    n = int(np.ceil(radius))
    fine = (np.arange((2 * n + 1) * 8) + 0.5) / 8.0 - (n + 0.5)
    yy, xx = np.meshgrid(fine, fine, indexing="ij")
    inside = (xx * xx + yy * yy <= radius * radius).astype(np.float32)
    k = inside.reshape(2 * n + 1, 8, 2 * n + 1, 8).mean(axis=(1, 3))
    return k / k.sum()


def _line_kernel(length: float, angle_deg: float) -> np.ndarray:
    """Normalised centred line kernel (uniform motion during the exposure), bilinear taps."""
    half = length / 2.0
    n = int(np.ceil(half)) + 1
    t = np.linspace(-half, half, max(2, int(np.ceil(length * 4)) + 1))
    x = n + t * np.cos(np.radians(angle_deg))
    y = n + t * np.sin(np.radians(angle_deg))
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    k = np.zeros((2 * n + 1, 2 * n + 1), np.float64)  # odd size: filter2D anchors at n
    for dy, dx, w in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)),
                      (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (y0 + dy, x0 + dx), w)
    return (k / k.sum()).astype(np.float32)


def _object_pattern(kind: str, shape: tuple[int, int], scale_px: float,
                    rng: np.random.Generator) -> np.ndarray:
    """Dark-feature map (0..1) of a touching object's texture, in artwork texture pixels.

    stripes: a grating of period ``scale_px`` at 30 deg; noise: blobs about ``scale_px``
    across (smoothed white noise above its 80th percentile: glyph-like dark specks); text:
    rows of random characters ``scale_px`` high; dark: no texture.
    """
    h, w = shape
    if kind == "stripes":
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        t = (xs * np.float32(np.cos(np.pi / 6)) + ys * np.float32(np.sin(np.pi / 6))) / scale_px
        return np.clip(0.5 + 2.0 * np.sin(np.float32(2 * np.pi) * t), 0.0, 1.0)
    if kind == "noise":
        step = max(scale_px / 2.0, 1.0)
        small = rng.standard_normal((int(h / step) + 2, int(w / step) + 2)).astype(np.float32)
        blurred = cv2.GaussianBlur(small, (0, 0), 0.7)
        big = cv2.resize(blurred, (w, h), interpolation=cv2.INTER_CUBIC)
        thr = np.percentile(big, 80)
        return np.clip((big - thr) / (0.5 * float(big.std()) + 1e-6), 0.0, 1.0)
    if kind == "text":
        canvas = np.zeros((h, w), np.uint8)
        font_scale = scale_px / 22.0  # HERSHEY_SIMPLEX capitals are ~22 units high at scale 1
        thick = max(1, int(round(scale_px / 8)))
        letters = np.array(list("ABCDEFGHJKLMNPRSTUVWXYZ0123456789 "))
        y = scale_px * 1.3
        while y < h + scale_px:
            line = "".join(rng.choice(letters, size=int(w / (scale_px * 0.8)) + 2))
            cv2.putText(canvas, line, (int(-rng.uniform(0, scale_px)), int(y)),
                        cv2.FONT_HERSHEY_SIMPLEX, font_scale, 255, thick, cv2.LINE_AA)
            y += scale_px * 1.6
        return canvas.astype(np.float32) / 255.0
    return np.zeros(shape, np.float32)


class Renderer:
    """Render stereo frames of the pad under contacts; deterministic for a seed."""

    def __init__(self, artwork: Artwork, rig: SimulatedCameraPair | None = None,
                 pad: PadParams | None = None, supersample: int = 2, iterations: int = 8,
                 mirrored: bool = False, grid: dict[str, float] | None = None) -> None:
        self.artwork = artwork
        self.rig = rig or SimulatedCameraPair()
        self.pad = pad or PadParams()
        self.ss = int(supersample)
        if self.ss < 1:
            raise ValueError("supersample must be >= 1")
        self.iterations = int(iterations)
        self.mirrored = bool(mirrored)
        self.grid = grid or {}
        self.pitch = artwork.pitch_m
        self._tables = [_RayTable(c, self.ss) for c in self.rig.cameras]
        self._texture = np.ascontiguousarray(artwork.albedo, dtype=np.float32)
        # rest position -> cell coordinates -> texture pixel (affine, separable)
        self.uc = (artwork.cols - 1) / 2.0
        self.vc = (artwork.rows - 1) / 2.0
        sx = -1.0 if self.mirrored else 1.0
        p00 = artwork.cell_to_pixel(np.array(self.vc), np.array(self.uc))
        p10 = artwork.cell_to_pixel(np.array(self.vc), np.array(self.uc + 1.0))
        self._tex_ax = float(p10[0] - p00[0]) * sx / self.pitch
        self._tex_bx = float(p00[0])
        self._tex_ay = float(artwork.pitch_px) / self.pitch
        self._tex_by = float(p00[1])
        self._tex_flat = [(t.X0_ss * self._tex_ax + self._tex_bx,
                           t.Y0_ss * self._tex_ay + self._tex_by) for t in self._tables]
        # arrays and tuples of arrays, keyed by what they are (first item) and their inputs
        self._cache: dict[tuple[Any, ...], Any] = {}

    # ------------------------------------------------------------------ geometry

    def cell_rest_positions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, X, Y) of every cell centre on the undeformed pad (pad frame)."""
        row_grid, col_grid = np.meshgrid(np.arange(self.artwork.rows),
                                         np.arange(self.artwork.cols), indexing="ij")
        rows, cols = row_grid.reshape(-1), col_grid.reshape(-1)
        sx = -1.0 if self.mirrored else 1.0
        X = sx * (cols - self.uc) * self.pitch
        Y = (rows - self.vc) * self.pitch
        return rows, cols, X, Y

    def build_field(self, contacts: Sequence[Contact | LoadContact]) -> FieldGrid:
        return FieldGrid.build(contacts, self.pad, **self.grid)

    def _cast(self, table: _RayTable, fld: FieldGrid
              ) -> tuple[np.ndarray, np.ndarray, tuple[slice, slice] | None]:
        """Rest positions hit by the pixel-centre rays, and the image window that moved."""
        X = table.X0.copy()
        Y = table.Y0.copy()
        if fld.active_box is None:
            return X, Y, None
        margin = fld.max_displacement() * 1.5 + 1e-4
        bx0, by0, bx1, by1 = fld.active_box
        mask = ((table.X0 > bx0 - margin) & (table.X0 < bx1 + margin)
                & (table.Y0 > by0 - margin) & (table.Y0 < by1 + margin))
        rows = np.flatnonzero(mask.any(axis=1))
        cols = np.flatnonzero(mask.any(axis=0))
        if rows.size == 0:
            return X, Y, None
        win = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
        x0, y0, a, b = table.X0[win], table.Y0[win], table.a[win], table.b[win]
        inv = np.float32(1.0 / fld.spacing)
        tx0, ty0 = fld.table_origin
        ox, oy = np.float32(tx0 / fld.spacing), np.float32(ty0 / fld.spacing)
        table5 = fld.table32
        xs, ys = x0.copy(), y0.copy()
        tol = 5e-7  # metres (0.02 px; cv2.remap interpolates in 1/32 grid steps)
        self.last_iterations = 0
        sub = (slice(0, xs.shape[0]), slice(0, xs.shape[1]))  # part still iterating
        for _ in range(self.iterations):
            sx, sy = xs[sub], ys[sub]
            sa, sb = a[sub], b[sub]
            u = cv2.remap(table5, sx * inv - ox, sy * inv - oy, cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            # Newton step on X - G(X) = 0 with G(X) = X0 + uz(X) (a, b) - (ux, uy)(X); the
            # Jacobian keeps the rank-one height term (the lateral terms are small).
            rx = x0[sub] + u[:, :, 2] * sa - u[:, :, 0] - sx
            ry = y0[sub] + u[:, :, 2] * sb - u[:, :, 1] - sy
            gx, gy = u[:, :, 3], u[:, :, 4]
            k = (gx * rx + gy * ry) / np.maximum(1.0 - gx * sa - gy * sb, np.float32(0.2))
            sx += rx + sa * k  # in place: sx, sy are views of xs, ys
            sy += ry + sb * k
            self.last_iterations += 1
            busy = (np.abs(rx) > tol) | (np.abs(ry) > tol)
            rows = np.flatnonzero(busy.any(axis=1))
            if rows.size == 0:
                break
            cols = np.flatnonzero(busy.any(axis=0))
            r0, c0 = sub[0].start, sub[1].start
            sub = (slice(r0 + rows[0], r0 + rows[-1] + 1), slice(c0 + cols[0], c0 + cols[-1] + 1))
        X[win] = xs
        Y[win] = ys
        return X, Y, win

    # ------------------------------------------------------------------ shading

    def _irradiance(self, P: np.ndarray, n: np.ndarray, nz: Nuisances) -> np.ndarray:
        """Lambertian irradiance from the point light plus ambient, 1 at the pad centre.

        P, n: (..., 3) positions (pad frame) and unit normals pointing at the cameras.
        """
        L = np.asarray(nz.light, dtype=np.float32)
        lx, ly, lz = L[0] - P[..., 0], L[1] - P[..., 1], L[2] - P[..., 2]
        dist2 = lx * lx + ly * ly + lz * lz
        cos = (lx * n[..., 0] + ly * n[..., 1] + lz * n[..., 2]) / np.sqrt(dist2)
        direct = np.maximum(cos, 0.0) / dist2
        ref = abs(L[2]) / float(L @ L) ** 1.5  # flat pad, centre
        E = nz.ambient + (1.0 - nz.ambient) * direct / ref
        gx, gy = nz.illumination_gradient
        if gx or gy:
            E = E * np.maximum(0.0, 1.0 + gx * P[..., 0] * 1e3 + gy * P[..., 1] * 1e3)
        return E.astype(np.float32)

    def _shadow_factor(self, X: np.ndarray, Y: np.ndarray, nz: Nuisances) -> np.ndarray | float:
        if not nz.shadows:
            return 1.0
        f = np.ones(np.shape(X), np.float32)
        for s in nz.shadows:
            cx, cy = float(s.get("x", 0.0)), float(s.get("y", 0.0))
            r = float(s.get("radius", 0.002))
            soft = max(float(s.get("softness", 0.0005)), 1e-6)
            strength = float(s.get("strength", 0.5))
            d = np.hypot(X - cx, Y - cy)
            t = np.clip((r - d) / soft + 0.5, 0.0, 1.0)
            f *= 1.0 - strength * (t * t * (3 - 2 * t))
        return f

    def _vignette(self, cam: Camera, strength: float) -> np.ndarray:
        key = ("vignette", cam.name, strength)
        if key not in self._cache:
            ys, xs = np.mgrid[0:cam.height, 0:cam.width].astype(np.float32)
            r2 = ((xs - cam.K[0, 2]) ** 2 + (ys - cam.K[1, 2]) ** 2) / (
                (cam.width / 2) ** 2 + (cam.height / 2) ** 2)
            self._cache[key] = (1.0 - strength * r2).astype(np.float32)
        return self._cache[key]

    def _flat_irradiance(self, index: int, nz: Nuisances) -> np.ndarray:
        key = ("flat", index, nz.light, nz.ambient, nz.illumination_gradient)
        if key not in self._cache:
            t = self._tables[index]
            P = np.stack([t.X0, t.Y0, np.zeros_like(t.X0)], axis=-1)
            n = np.zeros_like(P)
            n[..., 2] = -1.0
            self._cache[key] = self._irradiance(P, n, nz)
        return self._cache[key]

    # ------------------------------------------------------------------ robustness nuisances

    def _cell_index(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per texture pixel: its cell (row * cols + col, -1 off the pattern) and offset.

        The offset from the cell centre is (x, y) in cells: print damage is drawn per pixel
        from per-cell random values, without a loop over glyphs.
        """
        key = ("cells",)
        if key not in self._cache:
            art = self.artwork
            h, w = self._texture.shape
            sx = -1.0 if art.mirrored else 1.0
            cf = (np.arange(w, dtype=np.float32) - np.float32(art.cell00_px[0])) / np.float32(
                sx * art.pitch_px)
            rf = (np.arange(h, dtype=np.float32) - np.float32(art.cell00_px[1])) / np.float32(
                art.pitch_px)
            cc, rr = np.rint(cf).astype(np.int32), np.rint(rf).astype(np.int32)
            inside = ((rr[:, None] >= 0) & (rr[:, None] < art.rows)
                      & (cc[None, :] >= 0) & (cc[None, :] < art.cols))
            cell = np.where(inside, rr[:, None] * art.cols + cc[None, :], -1).astype(np.int32)
            dx = np.broadcast_to((cf - cc)[None, :], (h, w))
            dy = np.broadcast_to((rf - rr)[:, None], (h, w))
            self._cache[key] = (cell, dx, dy)
        return self._cache[key]

    def print_damage(self, nz: Nuisances, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Damaged artwork texture and, per cell (row-major), whether it is gone or damaged.

        The same for every frame of a seed (the print does not heal).  A cell that keeps
        less than 20 % of its ink counts as gone (not visible); one whose ink changed by
        more than 3 % as damaged.
        """
        key = ("damage", seed, nz.dropout, nz.wear, nz.scratches, nz.bubbles)
        if key in self._cache:
            return self._cache[key]
        art = self.artwork
        ncell = art.rows * art.cols
        rng = np.random.default_rng([int(seed), 104_729])
        cell, dx, dy = self._cell_index()
        a = self._texture.copy()
        valid = cell >= 0
        cid = np.where(valid, cell, 0)
        erase = np.zeros(a.shape, bool)
        if nz.dropout:
            erase |= valid & (rng.random(ncell) < nz.dropout)[cid]
        if nz.wear:
            worn = rng.random(ncell) < nz.wear
            theta = rng.uniform(0, 2 * np.pi, ncell).astype(np.float32)
            offset = rng.uniform(-0.05, 0.2, ncell).astype(np.float32)
            cut = dx * np.cos(theta)[cid] + dy * np.sin(theta)[cid] > offset[cid]
            erase |= valid & worn[cid] & cut
        a[erase] = 1.0
        ppc = float(art.pitch_px)  # texture pixels per cell
        h, w = a.shape
        if nz.scratches:
            m = np.zeros((h, w), np.uint8)
            c00 = np.asarray(art.cell00_px)
            for _ in range(int(nz.scratches)):
                p0 = c00 + rng.uniform(0, 1, 2) * np.array([art.cols - 1, art.rows - 1]) * ppc
                ang = rng.uniform(0, np.pi)
                half = rng.uniform(1.5, 5.0) * ppc
                d = half * np.array([np.cos(ang), np.sin(ang)])
                width = max(1, int(round(rng.uniform(0.04, 0.08) * ppc)))
                q0, q1 = np.rint((p0 - d) * 4).astype(int), np.rint((p0 + d) * 4).astype(int)
                cv2.line(m, (int(q0[0]), int(q0[1])), (int(q1[0]), int(q1[1])), 255, width,
                         cv2.LINE_AA, shift=2)
            mf = m.astype(np.float32) / 255.0
            a = a + (1.0 - a) * mf
        if nz.bubbles:
            ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
            c00 = np.asarray(art.cell00_px)
            for _ in range(int(nz.bubbles)):
                cx, cy = c00 + rng.uniform(0, 1, 2) * np.array([art.cols - 1, art.rows - 1]) * ppc
                r = rng.uniform(0.4, 1.2) * ppc
                y0, y1 = int(max(cy - r - 2, 0)), int(min(cy + r + 3, h))
                x0, x1 = int(max(cx - r - 2, 0)), int(min(cx + r + 3, w))
                dist = np.hypot(xs[y0:y1, x0:x1] - cx, ys[y0:y1, x0:x1] - cy)
                sub = a[y0:y1, x0:x1]
                inside = np.clip(r - dist + 0.5, 0.0, 1.0)  # faded ink: print lifted off
                sub = 1.0 - (1.0 - sub) * (1.0 - 0.55 * inside)
                rim = np.exp(-0.5 * ((dist - r) / (0.06 * r + 0.5)) ** 2)
                a[y0:y1, x0:x1] = sub * (1.0 - 0.45 * rim)
        ink0 = np.bincount(cid[valid], (1.0 - self._texture)[valid], ncell)
        ink1 = np.bincount(cid[valid], (1.0 - a)[valid], ncell)
        gone = ink1 < 0.2 * ink0
        damaged = np.abs(ink1 - ink0) > 0.03 * ink0
        out = (a.astype(np.float32), gone, damaged)
        self._cache = {k: v for k, v in self._cache.items() if k[0] != "damage"}
        self._cache[key] = out
        return out

    def _object_texture(self, nz: Nuisances, seed: int) -> np.ndarray:
        """Albedo of the touching object in artwork texture pixels (fixed per seed)."""
        key = ("object", seed, nz.see_through, nz.object_albedo, nz.object_contrast,
               nz.object_scale)
        if key not in self._cache:
            rng = np.random.default_rng([int(seed), 7_919])
            scale_px = nz.object_scale * abs(self._tex_ay)
            pattern = _object_pattern(nz.see_through, self._texture.shape, scale_px, rng)
            self._cache = {k: v for k, v in self._cache.items() if k[0] != "object"}
            self._cache[key] = (np.float32(nz.object_albedo)
                                - np.float32(nz.object_contrast) * pattern).astype(np.float32)
        return self._cache[key]

    def _contact_mask(self, fld: FieldGrid, nz: Nuisances) -> np.ndarray | None:
        """Contact area (0..1, soft edge) in texture pixels; None without contact.

        It is where the surface moved towards the cameras by at least
        ``object_depth_fraction`` of the largest displacement (Hertz: half the depth at the
        contact radius, so 0.5 is the contact disc of a sphere).
        """
        depth = -fld.data[:, :, 2]
        dmax = float(depth.max(initial=0.0))
        if dmax < 5e-6:
            return None
        m = np.clip((depth / dmax - nz.object_depth_fraction) / 0.05 + 0.5, 0.0, 1.0)
        sp = fld.spacing
        ax, ay = self._tex_ax, self._tex_ay  # texture pixel -> rest position -> field node
        M = np.array([[1.0 / (ax * sp), 0.0, -(self._tex_bx / ax + fld.x0) / sp],
                      [0.0, 1.0 / (ay * sp), -(self._tex_by / ay + fld.y0) / sp]])
        h, w = self._texture.shape
        return cv2.warpAffine(m.astype(np.float32), M, (w, h),
                              flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    def dust_specks(self, index: int, nz: Nuisances, seed: int) -> np.ndarray:
        """(n, 4) u, v, radius, strength of the dust specks on one camera (fixed per seed)."""
        cam = self.rig.cameras[index]
        rng = np.random.default_rng([int(seed), 15_485_863, index])
        n = int(nz.dust)
        u = rng.uniform(0, cam.width, n)
        v = rng.uniform(0, cam.height, n)
        r = nz.dust_radius_px * np.exp(rng.normal(0.0, 0.3, n))
        k = np.clip(nz.dust_strength * rng.uniform(0.6, 1.4, n), 0.0, 0.98)
        return np.stack([u, v, r, k], axis=1)

    def _dust_factor(self, index: int, nz: Nuisances, seed: int) -> np.ndarray:
        """Light transmitted past the dust specks of one camera (h, w)."""
        key = ("dust", index, seed, nz.dust, nz.dust_radius_px, nz.dust_strength)
        if key not in self._cache:
            cam = self.rig.cameras[index]
            mask = np.zeros((cam.height, cam.width), np.float32)
            for u, v, r, k in self.dust_specks(index, nz, seed):
                speck = np.zeros_like(mask)
                cv2.circle(speck, (int(round(u * 16)), int(round(v * 16))), int(round(r * 16)),
                           float(k), -1, cv2.LINE_AA, shift=4)
                np.maximum(mask, speck, out=mask)
            self._cache[key] = 1.0 - cv2.GaussianBlur(mask, (0, 0), 0.7)
        return self._cache[key]

    def render_camera(  # noqa: C901 - the nuisances, one pass in a fixed order
            self, index: int, fld: FieldGrid, nz: Nuisances, rng: np.random.Generator,
            exposure: float, color: bool, seed: int = 0, ink_cells: np.ndarray | None = None,
            linear: bool = False) -> np.ndarray:
        """One camera's image (uint8, grey or BGR); ``seed`` fixes print damage and dust.

        ``ink_cells`` (bool per cell, row-major): print only these cells' glyphs (paper
        elsewhere). ``linear``: return the float32 signal in grey levels before read and shot
        noise, gamma, 8-bit quantisation and MJPEG (what a noise model acts on).
        """
        cam = self.rig.cameras[index]
        table = self._tables[index]
        h, w = cam.height, cam.width
        X, Y, win = self._cast(table, fld)
        tex_x, tex_y = self._tex_flat[index]
        E = self._flat_irradiance(index, nz)
        if win is not None:
            # Supersample positions: exact flat-plane hits plus the (smooth) deformation
            # correction cast at pixel centres, interpolated.
            dX = (X - table.X0) * np.float32(self._tex_ax)  # texture-pixel correction
            dY = (Y - table.Y0) * np.float32(self._tex_ay)
            if self.ss > 1:
                dX = cv2.resize(dX, (w * self.ss, h * self.ss), interpolation=cv2.INTER_LINEAR)
                dY = cv2.resize(dY, (w * self.ss, h * self.ss), interpolation=cv2.INTER_LINEAR)
            tex_x = tex_x + dX
            tex_y = tex_y + dY
            # Shading varies slowly (surface normals change over the contact's size): it is
            # computed on 2x2 pixel blocks of the moved window and interpolated back.
            win = _even_window(win, h, w)
            wh, ww = X[win].shape
            xs = cv2.resize(X[win], (ww // 2, wh // 2), interpolation=cv2.INTER_AREA)
            ys = cv2.resize(Y[win], (ww // 2, wh // 2), interpolation=cv2.INTER_AREA)
            inv = np.float32(1.0 / fld.spacing)
            tx0, ty0 = fld.table_origin
            mx = xs * inv - np.float32(tx0 / fld.spacing)
            my = ys * inv - np.float32(ty0 / fld.spacing)
            u = cv2.remap(fld.table32, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                          borderValue=0)
            P = np.stack([xs + u[..., 0], ys + u[..., 1], u[..., 2]], axis=-1)
            n = np.stack([u[..., 3], u[..., 4], -np.ones_like(xs)], axis=-1)
            n /= np.sqrt((n * n).sum(axis=-1, keepdims=True))
            E = E.copy()
            E[win] = cv2.resize(self._irradiance(P, n, nz), (ww, wh),
                                interpolation=cv2.INTER_LINEAR)
        texture = self.print_damage(nz, seed)[0] if nz.damages_print else self._texture
        if ink_cells is not None:
            cell = self._cell_index()[0]
            printed = np.asarray(ink_cells, bool).ravel()[np.where(cell >= 0, cell, 0)]
            texture = np.where((cell >= 0) & printed, texture, np.float32(1.0))
        mask = self._contact_mask(fld, nz) if nz.see_through else None
        seen = None
        if mask is None:
            albedo = cv2.remap(texture, tex_x, tex_y, cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=1.0)
            if self.ss > 1:
                albedo = cv2.resize(albedo, (w, h), interpolation=cv2.INTER_AREA)
        else:
            # The object replaces the pad's white backdrop between the glyphs in the contact
            # area: reflectance ink + (paper - ink) a - paper m a + object m a, linear in
            # (a, m a, object m a), so these three are sampled and anti-aliased together.
            ma = mask * texture
            stack = np.dstack([texture, ma, self._object_texture(nz, seed) * ma])
            tex3 = cv2.remap(stack, tex_x, tex_y, cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=(1.0, 0.0, 0.0))
            if self.ss > 1:
                tex3 = cv2.resize(tex3, (w, h), interpolation=cv2.INTER_AREA)
            albedo, seen = tex3[:, :, 0], tex3[:, :, 1:]
        E = E * self._shadow_factor(X, Y, nz)
        channels = 3 if color else 1
        out: np.ndarray = np.empty((h, w, channels), np.float32)  # cv2 filters replace it
        for c in range(channels):
            ink = nz.ink[c] if color else float(np.mean(nz.ink))
            paper = nz.paper[c] if color else float(np.mean(nz.paper))
            refl = ink + (paper - ink) * albedo
            if seen is not None:
                refl = refl - paper * seen[:, :, 0] + seen[:, :, 1]
            out[:, :, c] = refl * E
        for occ in nz.occluders:
            if occ.get("camera", "both") not in ("both", cam.name):
                continue
            mask = np.zeros((h, w), np.float32)
            cv2.circle(mask, (int(occ.get("u", w / 2)), int(occ.get("v", h / 2))),
                       int(occ.get("radius", 20)), 1.0, -1, lineType=cv2.LINE_AA)
            soft = float(occ.get("softness", 6.0))
            mask = cv2.GaussianBlur(mask, (0, 0), soft) if soft > 0 else mask
            out *= (1.0 - float(occ.get("strength", 0.6)) * mask)[:, :, None]
        if nz.dust:
            out *= self._dust_factor(index, nz, seed)[:, :, None]
        if nz.blur_sigma > 0:
            out = cv2.GaussianBlur(out, (0, 0), nz.blur_sigma).reshape(h, w, channels)
        if nz.defocus_px > 0:
            out = cv2.filter2D(out, -1, _pillbox(nz.defocus_px),
                               borderType=cv2.BORDER_REFLECT).reshape(h, w, channels)
        if nz.motion_blur_px > 0:
            out = cv2.filter2D(out, -1, _line_kernel(nz.motion_blur_px, nz.motion_blur_angle_deg),
                               borderType=cv2.BORDER_REFLECT).reshape(h, w, channels)
        if nz.vignetting:
            out *= self._vignette(cam, nz.vignetting)[:, :, None]
        signal = out * np.float32(255.0 * nz.white_level / float(np.mean(nz.paper)) * exposure)
        if linear:
            return signal[:, :, 0] if channels == 1 else signal
        if nz.shot_noise > 0 or nz.noise_sigma > 0:
            std = np.sqrt(np.float32(nz.noise_sigma**2)
                          + np.float32(nz.shot_noise) * np.maximum(signal, 0.0))
            signal = signal + std * rng.standard_normal(signal.shape, dtype=np.float32)
        unit = np.clip(signal * np.float32(1 / 255.0), 0.0, 1.0)
        if nz.gamma != 1.0:
            unit = unit ** np.float32(1.0 / nz.gamma)
        img = np.rint(unit * np.float32(255.0)).astype(np.uint8)
        img = img[:, :, 0] if channels == 1 else img
        if nz.jpeg_quality:
            ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(nz.jpeg_quality)])
            img = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE if channels == 1 else cv2.IMREAD_COLOR)
        return img

    # ------------------------------------------------------------------ ground truth

    def hit_rest_position(self, cam: Camera, px: np.ndarray, fld: FieldGrid,
                          iterations: int = 40) -> np.ndarray:
        """Rest positions hit by rays through pixels (float64, exact field): occlusion test."""
        d = cam.rays(px)
        x0 = cam.C[0] - cam.C[2] * d[:, 0]
        y0 = cam.C[1] - cam.C[2] * d[:, 1]
        xs, ys = x0.copy(), y0.copy()
        if fld.active_box is not None:
            for _ in range(iterations):
                u = fld.sample(xs, ys)
                nx = x0 + u[:, 2] * d[:, 0] - u[:, 0]
                ny = y0 + u[:, 2] * d[:, 1] - u[:, 1]
                change = float(np.abs(np.concatenate([nx - xs, ny - ys])).max(initial=0.0))
                xs, ys = nx, ny
                if change < 1e-12:
                    break
        return np.stack([xs, ys], axis=1)

    def ground_truth(self, fld: FieldGrid, nz: Nuisances | None = None,
                     margin_px: float | None = None, seed: int = 0) -> GroundTruth:
        """True cell centres on the deformed pad and their visibility in both images.

        With print damage, glyphs worn off are not visible and damaged ones (or ones under a
        dust speck) are flagged in :attr:`GroundTruth.damaged`.
        """
        rows, cols, X, Y = self.cell_rest_positions()
        u = fld.sample(X, Y)
        world = np.stack([X + u[:, 0], Y + u[:, 1], u[:, 2]], axis=1)
        if margin_px is None:
            margin_px = 0.5 * self.pitch * self.rig.pixels_per_metre_at_pad()
        visible = np.ones(len(rows), bool)
        pxs = []
        for cam in self.rig.cameras:
            in_front = cam.to_camera(world)[:, 2] > 1e-4
            px = cam.project(world)
            inside = ((px[:, 0] >= margin_px) & (px[:, 0] <= cam.width - 1 - margin_px)
                      & (px[:, 1] >= margin_px) & (px[:, 1] <= cam.height - 1 - margin_px))
            ok = in_front & inside
            if ok.any() and fld.active_box is not None:
                hit = self.hit_rest_position(cam, px[ok], fld)
                err = np.hypot(hit[:, 0] - X[ok], hit[:, 1] - Y[ok])
                sub = np.flatnonzero(ok)
                ok[sub[err > 0.02 * self.pitch]] = False  # another part of the pad is in front
            if nz is not None and nz.shadows:
                ok &= np.asarray(self._shadow_factor(X, Y, nz)) > 0.3
            if nz is not None:
                for occ in nz.occluders:
                    if occ.get("camera", "both") in ("both", cam.name) and \
                            float(occ.get("strength", 0.6)) > 0.7:
                        dist = np.hypot(px[:, 0] - float(occ.get("u", cam.width / 2)),
                                        px[:, 1] - float(occ.get("v", cam.height / 2)))
                        ok &= dist > float(occ.get("radius", 20))
            visible &= ok
            pxs.append(px)
        xyz = self.rig.world_to_left(world)
        damaged = None
        if nz is not None and (nz.damages_print or nz.dust):
            damaged = np.zeros(len(rows), bool)
            if nz.damages_print:
                _tex, gone, bad = self.print_damage(nz, seed)
                visible &= ~gone
                damaged |= bad
            if nz.dust:
                spacing = self.pitch * self.rig.pixels_per_metre_at_pad()
                for index, px in enumerate(pxs):
                    specks = self.dust_specks(index, nz, seed)
                    specks = specks[specks[:, 3] > 0.15]
                    if len(specks):
                        d = np.hypot(px[:, None, 0] - specks[None, :, 0],
                                     px[:, None, 1] - specks[None, :, 1])
                        damaged |= (d < specks[None, :, 2] + 0.4 * spacing).any(axis=1)
        return GroundTruth(rows, cols, xyz, world, pxs[0], pxs[1], visible, damaged=damaged)

    # ------------------------------------------------------------------ frames

    def touch_truth(self, contacts: Sequence[Contact | LoadContact], fld: FieldGrid,
                    truth: GroundTruth) -> TouchTruth:
        """Force, contact and per-cell displacement truth of a frame (pad frame)."""
        if self.mirrored:
            raise ValueError("touch ground truth needs a non-mirrored view")
        rows, cols, X, Y = self.cell_rest_positions()
        v = truth.visible
        traction = fld.traction if fld.traction is not None else np.zeros((fld.ny, fld.nx, 3))
        return touch_truth(contacts, traction, fld.data[:, :, 2], fld.xs, fld.ys, fld.spacing,
                           (X, Y), (rows[v], cols[v], truth.world[v], fld.sample(X[v], Y[v])))

    def render(self, contacts: Sequence[Contact | LoadContact],
               nuisances: Nuisances | None = None,
               seed: int = 0, frame_index: int = 0, color: bool = False,
               ink_cells: np.ndarray | None = None, linear: bool = False) -> StereoFrame:
        """Render one stereo frame and its ground truth (deterministic for seed, frame).

        With load contacts the truth carries :attr:`GroundTruth.touch`. ``ink_cells`` and
        ``linear`` as in :meth:`render_camera` (for analyses: a glyph's own share of the
        image, the noise-free signal); the same seed gives the same scene either way.
        """
        nz = nuisances or Nuisances()
        cells = self.artwork.rows * self.artwork.cols
        if ink_cells is not None and np.asarray(ink_cells).size != cells:
            raise ValueError(f"ink_cells has {np.asarray(ink_cells).size} entries; the artwork "
                             f"has {cells} cells (row-major)")
        fld = self.build_field(contacts)
        rng = np.random.default_rng([int(seed), int(frame_index)])
        exposure = nz.exposure * (1.0 + nz.exposure_jitter * float(rng.standard_normal())) \
            if nz.exposure_jitter else nz.exposure
        exposure = max(exposure, 0.0)
        exp_l = exp_r = exposure
        if nz.exposure_right != 1.0 or nz.exposure_jitter_camera:
            # own stream, so scenes without these keep their exact noise
            j = nz.exposure_jitter_camera * np.random.default_rng(
                [int(seed), int(frame_index), 2]).standard_normal(2)
            exp_l = max(exposure * (1.0 + float(j[0])), 0.0)
            exp_r = max(exposure * nz.exposure_right * (1.0 + float(j[1])), 0.0)
        left = self.render_camera(0, fld, nz, rng, exp_l, color, seed, ink_cells, linear)
        right = self.render_camera(1, fld, nz, rng, exp_r, color, seed, ink_cells, linear)
        truth = self.ground_truth(fld, nz, seed=seed)
        if any(is_load(c) for c in contacts):
            truth.touch = self.touch_truth(contacts, fld, truth)
        return StereoFrame(left, right, truth, fld)

    def render_plane(self, index: int, R_board: np.ndarray, t_board: np.ndarray,
                     albedo_fn: Any, background: float = 0.45, noise_sigma: float = 0.5,
                     blur_sigma: float = 0.4, rng: np.random.Generator | None = None
                     ) -> np.ndarray:
        """Image of a rigid planar target (calibration board) in the pad frame.

        The board's point (u, v) is at ``t_board + R_board @ (u, v, 0)``; ``albedo_fn(u, v)``
        gives its albedo. Same cached rays and anti-aliasing as the pad.
        """
        cam = self.rig.cameras[index]
        table = self._tables[index]
        n = R_board[:, 2]
        a = table.a_ss.reshape(-1).astype(np.float64)
        b = table.b_ss.reshape(-1).astype(np.float64)
        d = np.stack([a, b, np.ones_like(a)], axis=1)
        denom = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            s = ((t_board - cam.C) @ n) / denom
        P = cam.C[None, :] + s[:, None] * d - t_board[None, :]
        uv = P @ R_board[:, :2]
        albedo = albedo_fn(uv[:, 0], uv[:, 1])
        albedo = np.where((s > 0) & np.isfinite(s), albedo, background).astype(np.float32)
        img = cv2.resize(albedo.reshape(table.shape_ss), (cam.width, cam.height),
                         interpolation=cv2.INTER_AREA) if self.ss > 1 else \
            albedo.reshape(table.shape_ss)
        if blur_sigma > 0:
            img = cv2.GaussianBlur(img, (0, 0), blur_sigma)
        img = img * 230.0
        if noise_sigma > 0:
            rng = rng or np.random.default_rng(0)
            img = img + noise_sigma * rng.standard_normal(img.shape)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)
