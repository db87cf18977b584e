"""The pad's linear-elastic surface response, shared by the simulator and the decoder's touch stage.

Everything is in the pad frame (CONTRACT.md, "Touch"): X, Y in the rest surface, Z the outward
normal (from the cameras through the pad towards the object); the elastomer fills Z < 0.
A force or traction is what the object exerts on the pad (pressing in: f_z < 0), and a
displacement u_z < 0 is an indentation. SI units throughout (m, N, Pa).

Two pads are modelled, both isotropic and linear (small strains, tractions acting at their
rest positions on Z = 0):

* ``thickness == 0``: an elastic half-space. Surface Green's function of Boussinesq and
  Cerruti, K.L. Johnson, Contact Mechanics, 1985, eqs. 2.18-2.19 at z = 0, mapped to the pad
  frame (Johnson's z points into the solid = -Z here; his normal load P = -f_z).
* ``thickness > 0``: a layer bonded to a rigid window at Z = -h (u = 0 there). Its surface
  compliance per wavenumber k = |k| (see :func:`layer_compliance`) is derived from the
  Papkovich-type solution of Navier's equation for one Fourier mode, u ~ (A + B Z) e^{+-kZ}
  (J.R. Barber, Elasticity, 3rd ed., 2010, ch. 30 (plane strain solutions in Fourier form)
  and §20.3 for the antiplane part); the four boundary conditions (traction at Z = 0, no
  displacement at Z = -h) were solved symbolically. In real space the layer is the closed-form
  half-space kernel plus a smooth correction computed by Hankel transforms.
"""
from __future__ import annotations

import functools
import math
import numbers
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft
from scipy import interpolate, special

# Above this k h the layer's compliance equals the half-space's to better than 1e-10
# (the differences decay as (kh)^2 e^{-2kh}).
HALF_SPACE_KH = 15.0
# Beyond this distance over the thickness a bonded layer's surface response is below
# 1e-12 of the half-space's (it decays exponentially, measured in the tests): exactly zero.
LAYER_CUTOFF_RHO = 40.0
# The layer's correction varies on the scale of its thickness h and is averaged over a cell
# of side s by n x n Gauss-Legendre points, n = ceil(3 s / h) <= LAYER_GAUSS_POINTS; a layer
# thinner than 3 s / LAYER_GAUSS_POINTS (s / 4) would be under-sampled: refused (against a
# 80 x 80-point average the kernel is good to 1e-5 at h = s / 5, 1.4 % off at s / 8 and 60 %
# at s / 12; below s / 40 the cut-off zeroes the whole kernel and the inversion fails).
LAYER_GAUSS_POINTS = 12
MIN_LAYER_CELLS = 3.0 / LAYER_GAUSS_POINTS


def _real(v: object) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


@dataclass(frozen=True)
class Elastomer:
    """Isotropic linear-elastic pad; frozen and hashable so kernels can be cached per pad."""

    youngs_modulus: float  # Pa
    poisson_ratio: float
    thickness: float = 0.0  # m; 0 = elastic half-space, > 0 = layer bonded to a rigid window

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise ValueError naming the first property that is physically meaningless."""
        e, nu, h = self.youngs_modulus, self.poisson_ratio, self.thickness
        if not _real(e) or not math.isfinite(e) or e <= 0:
            raise ValueError(f"elastomer youngs_modulus must be a finite number > 0 Pa, got {e!r}")
        if not _real(nu) or not math.isfinite(nu) or not 0.0 <= nu <= 0.5:
            raise ValueError(f"elastomer poisson_ratio must be in [0, 0.5], got {nu!r}")
        if not _real(h) or not math.isfinite(h) or h < 0:
            raise ValueError("elastomer thickness must be a finite number >= 0 m "
                             f"(0 = half-space), got {h!r}")

    @property
    def shear_modulus(self) -> float:
        """Shear modulus mu = E / (2 (1 + nu)) in Pa (Johnson 1985, §2.1)."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))


# --------------------------------------------------------------------------- point kernel


def point_green(elastomer: Elastomer, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Half-space surface displacement u_i (m) at (x, y) per unit point force f_j (N) at 0.

    Returns (..., 3, 3) [i, j]. Johnson 1985 eqs. 2.18-2.19 at z = 0 in the pad frame, with
    c = 1/(pi E), r = |(x, y)|:
    G_xx = (1+nu) c [(1-nu)/r + nu x^2/r^3], G_xy = (1+nu) c nu x y / r^3,
    G_zz = (1-nu^2) c / r, G_xz = -G_zx = (1+nu)(1-2nu) x / (2 pi E r^2) (y alike).
    Singular at r = 0 (use :func:`cell_kernel` for distributed loads). Half-space only.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    E, nu = elastomer.youngs_modulus, elastomer.poisson_ratio
    r = np.hypot(x, y)
    if np.any(r == 0):
        raise ValueError("point_green is singular at r = 0")
    c = (1.0 + nu) / (np.pi * E)
    g = np.empty(x.shape + (3, 3))
    g[..., 0, 0] = c * ((1 - nu) / r + nu * x * x / r**3)
    g[..., 1, 1] = c * ((1 - nu) / r + nu * y * y / r**3)
    g[..., 0, 1] = g[..., 1, 0] = c * nu * x * y / r**3
    g[..., 2, 2] = (1 - nu * nu) / (np.pi * E * r)
    b = (1 + nu) * (1 - 2 * nu) / (2 * np.pi * E * r * r)
    g[..., 0, 2] = b * x
    g[..., 1, 2] = b * y
    g[..., 2, 0] = -b * x
    g[..., 2, 1] = -b * y
    return g


# --------------------------------------------------------------------------- layer, Fourier


def layer_compliance(kh: np.ndarray, nu: float) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                           np.ndarray]:
    """Dimensionless surface compliances (L, T, Z, Q) of a bonded layer at k h = ``kh``.

    For a traction mode q e^{i k.x} (k = |k| along the unit vector e) the surface
    displacement is u = C q / (mu k) with, in the (longitudinal e, transverse, normal) basis,
    u_L = L q_L - i Q q_z, u_T = T q_T, u_Z = i Q q_L + Z q_z, where with kappa = 3 - 4 nu,
    t = k h and D = kappa cosh 2t + 2 t^2 + (1 + kappa^2) / 2:
    L = (1-nu)(kappa sinh 2t + 2t) / D, Z = (1-nu)(kappa sinh 2t - 2t) / D,
    Q = [(1-2nu) kappa (cosh 2t - 1) - 2 t^2] / (2 D), T = tanh t (antiplane shear).
    Derived by solving Navier's equation for one mode (see the module docstring); the
    half-space values are L = Z = 1 - nu, Q = (1 - 2 nu)/2, T = 1 (Johnson 1985, eq. 2.19
    Fourier-transformed), reached for t > HALF_SPACE_KH. k -> 0: u_t = q h / mu,
    u_z = p h (1 - 2 nu) / (2 mu (1 - nu)) (uniaxial strain).
    """
    t = np.asarray(kh, dtype=np.float64)
    if np.any(t < 0):
        raise ValueError("k h must be >= 0")
    kappa = 3.0 - 4.0 * nu
    L = np.full(t.shape, 1.0 - nu)
    Z = np.full(t.shape, 1.0 - nu)
    Q = np.full(t.shape, (1.0 - 2.0 * nu) / 2.0)
    T = np.ones(t.shape)
    m = t <= HALF_SPACE_KH
    s = t[m]
    D = kappa * np.cosh(2 * s) + 2 * s * s + (1 + kappa * kappa) / 2
    sh = np.sinh(2 * s)
    L[m] = (1 - nu) * (kappa * sh + 2 * s) / D
    Z[m] = (1 - nu) * (kappa * sh - 2 * s) / D
    Q[m] = ((1 - 2 * nu) * kappa * 2 * np.sinh(s) ** 2 - 2 * s * s) / (2 * D)
    T[m] = np.tanh(s)
    return L, T, Z, Q


def fourier_compliance(elastomer: Elastomer, kx: np.ndarray, ky: np.ndarray) -> np.ndarray:
    """(..., 3, 3) complex surface compliance u^_i / q^_j (m/Pa * m^2) at wavevector (kx, ky).

    Convention f^(k) = integral f(x) e^{-i k.x} d^2x. Half-space: 2 (1-nu^2) / (E k) normal
    (Johnson 1985 eq. 2.19 transformed); layer: :func:`layer_compliance`. k = 0 gives the
    layer's uniaxial limits (infinite for the half-space: raises).
    """
    kx = np.asarray(kx, dtype=np.float64)
    ky = np.asarray(ky, dtype=np.float64)
    k = np.hypot(kx, ky)
    mu, nu, h = elastomer.shear_modulus, elastomer.poisson_ratio, elastomer.thickness
    if h == 0 and np.any(k == 0):
        raise ValueError("the half-space compliance is infinite at k = 0")
    L, T, Z, Q = layer_compliance(k * h if h > 0 else np.full(k.shape, np.inf), nu)
    safe = np.where(k > 0, k, 1.0)
    cx, cy = np.where(k > 0, kx / safe, 0.0), np.where(k > 0, ky / safe, 0.0)
    with np.errstate(divide="ignore"):
        scale = np.where(k > 0, 1.0 / (mu * safe), 0.0)
    out = np.zeros(k.shape + (3, 3), dtype=np.complex128)
    out[..., 0, 0] = (cx * cx * L + cy * cy * T) * scale
    out[..., 1, 1] = (cy * cy * L + cx * cx * T) * scale
    out[..., 0, 1] = out[..., 1, 0] = cx * cy * (L - T) * scale
    out[..., 0, 2] = -1j * cx * Q * scale
    out[..., 1, 2] = -1j * cy * Q * scale
    out[..., 2, 0] = 1j * cx * Q * scale
    out[..., 2, 1] = 1j * cy * Q * scale
    out[..., 2, 2] = Z * scale
    if h > 0 and np.any(k == 0):  # uniaxial limits, L/(mu k) -> h/mu etc.
        z = k == 0
        out[z] = 0.0
        out[z, 0, 0] = out[z, 1, 1] = h / mu
        out[z, 2, 2] = h * (1 - 2 * nu) / (2 * mu * (1 - nu))
    return out


def layer_quadrature() -> tuple[np.ndarray, np.ndarray]:
    """Nodes t = k h and weights of the layer-minus-half-space integrals over [0, HALF_SPACE_KH].

    Composite Gauss-Legendre, 60 panels of 12 nodes (the integrands decay as t^2 e^{-2t}
    and are smooth, so each panel's rule is exact to its polynomial order).
    """
    panels, order = 60, 12
    xg, wg = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, HALF_SPACE_KH, panels + 1)
    half = np.diff(edges) / 2
    t = (edges[:-1, None] + half[:, None] * (xg[None, :] + 1)).ravel()
    w = (half[:, None] * wg[None, :]).ravel()
    return t, w


@functools.lru_cache(maxsize=8)
def _layer_correction_table(nu: float) -> tuple[np.ndarray, interpolate.CubicSpline]:
    """Radial integrals of the layer-minus-half-space response, tabulated in rho = r / h.

    Returns (rho, spline of I over rho), I of shape (4, n):
    I_A = int [(L+T)/2 - (2-nu)/2] J0(t rho) dt, I_B = int [(L-T)/2 + nu/2] J2 dt,
    I_Q = int [Q - (1-2nu)/2] J1 dt,
    I_Z = int [Z - (1-nu)] J0 dt over t = k h in [0, HALF_SPACE_KH] (the inverse 2-D Fourier
    transform of a cos(n phi) term is a Hankel transform of order n; I.S. Gradshteyn,
    I.M. Ryzhik, Table of Integrals, 7th ed., 8.411.1). The integrands decay as t^2 e^{-2t}.
    """
    t, w = layer_quadrature()
    L, T, Z, Q = layer_compliance(t, nu)
    fa = ((L + T) / 2 - (2 - nu) / 2) * w
    fb = ((L - T) / 2 + nu / 2) * w
    fq = (Q - (1 - 2 * nu) / 2) * w
    fz = (Z - (1 - nu)) * w
    rho = np.linspace(0.0, LAYER_CUTOFF_RHO, 2001)
    out = np.empty((4, rho.size))
    for sl in np.array_split(np.arange(rho.size), 4):  # bounded memory
        arg = rho[sl, None] * t[None, :]
        j0, j1 = special.j0(arg), special.j1(arg)
        with np.errstate(divide="ignore", invalid="ignore"):
            j2 = np.where(arg > 1e-8, 2 * j1 / np.where(arg > 0, arg, 1.0) - j0, arg**2 / 8)
        out[0, sl] = j0 @ fa
        out[1, sl] = j2 @ fb
        out[2, sl] = j1 @ fq
        out[3, sl] = j0 @ fz
    return rho, interpolate.CubicSpline(rho, out, axis=1)


def _layer_correction(elastomer: Elastomer, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(..., 3, 3) point-kernel correction layer - half-space at (x, y) (smooth, finite)."""
    h, nu, mu = elastomer.thickness, elastomer.poisson_ratio, elastomer.shear_modulus
    _, spline = _layer_correction_table(float(nu))
    r = np.hypot(x, y)
    IA, IB, IQ, IZ = spline(np.minimum(r / h, LAYER_CUTOFF_RHO))
    safe = np.where(r > 0, r, 1.0)
    c, s = np.where(r > 0, x / safe, 0.0), np.where(r > 0, y / safe, 0.0)
    c2, s2 = c * c - s * s, 2 * c * s
    f = 1.0 / (2 * np.pi * mu * h)
    g = np.empty(np.shape(x) + (3, 3))
    g[..., 0, 0] = f * (IA - IB * c2)
    g[..., 1, 1] = f * (IA + IB * c2)
    g[..., 0, 1] = g[..., 1, 0] = -f * IB * s2
    g[..., 0, 2] = f * IQ * c
    g[..., 1, 2] = f * IQ * s
    g[..., 2, 0] = -f * IQ * c
    g[..., 2, 1] = -f * IQ * s
    g[..., 2, 2] = f * IZ
    return g


# --------------------------------------------------------------------------- cell kernel


def _square_integrals(xc: np.ndarray, yc: np.ndarray) -> dict[str, np.ndarray]:
    """Integrals of 1/r, x^2/r^3, y^2/r^3, xy/r^3, x/r^2, y/r^2 over grid rectangles.

    ``xc``, ``yc``: increasing 1-D corner coordinates (never 0); returns (len(yc) - 1,
    len(xc) - 1) arrays, one per rectangle [yc[i], yc[i+1]] x [xc[j], xc[j+1]]. Closed-form
    antiderivatives F with d2F/dxdy = f, evaluated once per corner and differenced (the
    construction of A.E.H. Love, Phil. Trans. A 228, 1929, for a uniformly loaded
    rectangle; Johnson 1985 §3.2): 1/r: x asinh(y/|x|) + y asinh(x/|y|); x^2/r^3:
    y asinh(x/|y|); y^2/r^3: x asinh(y/|x|); xy/r^3: -r; x/r^2: x atan(y/x) + y ln r.
    asinh keeps ln(y + r) accurate where y + r cancels.
    """
    X, Y = np.meshgrid(xc, yc)
    fx = X * np.arcsinh(Y / np.abs(X))
    fy = Y * np.arcsinh(X / np.abs(Y))
    lr = 0.5 * np.log(X * X + Y * Y)
    corners = {"inv_r": fx + fy, "xx": fy, "yy": fx, "xy": -np.hypot(X, Y),
               "x": X * np.arctan(Y / X) + Y * lr, "y": Y * np.arctan(X / Y) + X * lr}
    return {k: F[1:, 1:] - F[:-1, 1:] - F[1:, :-1] + F[:-1, :-1] for k, F in corners.items()}


def _check_grid(spacing: float, rows: int, cols: int) -> None:
    if not (_real(spacing) and math.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing must be a finite number > 0 m, got {spacing!r}")
    if int(rows) != rows or int(cols) != cols or rows < 1 or cols < 1:
        raise ValueError(f"rows and cols must be integers >= 1, got {rows!r}, {cols!r}")


def check_layer_resolved(elastomer: Elastomer, spacing: float) -> None:
    """Raise ValueError for a layer too thin for the cell kernel at this cell spacing (m).

    The layer's correction to the half-space varies on the scale of the thickness and is
    averaged over each cell by at most ``LAYER_GAUSS_POINTS`` x ``LAYER_GAUSS_POINTS``
    points, which resolves a thickness down to ``MIN_LAYER_CELLS`` (a quarter) of the
    spacing.  A half-space (thickness 0) and thicker layers pass.
    """
    h = elastomer.thickness
    thinnest = MIN_LAYER_CELLS * float(spacing)
    if 0 < h < thinnest:
        raise ValueError(
            f"elastomer thickness {h:.3g} m is below a quarter of the cell pitch "
            f"({thinnest:.3g} m for pitch {float(spacing):.3g} m): the layer model cannot "
            f"resolve it; use 0 for a half-space or a layer of at least {thinnest:.3g} m")


@functools.lru_cache(maxsize=16)
def _cell_kernel_cached(elastomer: Elastomer, spacing: float, rows: int, cols: int
                        ) -> np.ndarray:
    s = float(spacing)
    dr = np.arange(-(rows - 1), rows, dtype=np.float64)
    dc = np.arange(-(cols - 1), cols, dtype=np.float64)
    X, Y = np.meshgrid(dc * s, dr * s)  # (2 rows - 1, 2 cols - 1): rows along Y
    E, nu = elastomer.youngs_modulus, elastomer.poisson_ratio
    # field minus source point ranges over the cell [X - s/2, X + s/2] x [Y - s/2, Y + s/2]
    ints = _square_integrals(np.append(dc - 0.5, dc[-1] + 0.5) * s,
                          np.append(dr - 0.5, dr[-1] + 0.5) * s)
    area = s * s
    c = (1 + nu) / (np.pi * E * area)
    b = (1 + nu) * (1 - 2 * nu) / (2 * np.pi * E * area)
    K = np.empty(X.shape + (3, 3))
    K[..., 0, 0] = c * ((1 - nu) * ints["inv_r"] + nu * ints["xx"])
    K[..., 1, 1] = c * ((1 - nu) * ints["inv_r"] + nu * ints["yy"])
    K[..., 0, 1] = K[..., 1, 0] = c * nu * ints["xy"]
    K[..., 2, 2] = (1 - nu * nu) / (np.pi * E * area) * ints["inv_r"]
    K[..., 0, 2], K[..., 1, 2] = b * ints["x"], b * ints["y"]
    K[..., 2, 0], K[..., 2, 1] = -b * ints["x"], -b * ints["y"]
    h = elastomer.thickness
    if h > 0:
        # Smooth correction, averaged over the source cell by n x n Gauss-Legendre points
        # (it varies on the scale of h; check_layer_resolved keeps n within the cap).
        n = int(np.clip(np.ceil(3.0 * s / h), 1, LAYER_GAUSS_POINTS))
        xg, wg = np.polynomial.legendre.leggauss(n)
        corr = np.zeros_like(K)
        for xi, wi in zip(xg * s / 2, wg / 2):
            for yj, wj in zip(xg * s / 2, wg / 2):
                corr += wi * wj * _layer_correction(elastomer, X - xi, Y - yj)
        K += corr
        far = np.hypot(X, Y) > LAYER_CUTOFF_RHO * h - s
        K[far] = 0.0
    K.setflags(write=False)
    return K


def cell_kernel(elastomer: Elastomer, spacing: float, rows: int, cols: int) -> np.ndarray:
    """Surface displacement per unit force spread uniformly over one square cell.

    Returns K of shape (2 rows - 1, 2 cols - 1, 3, 3), float64: K[dr + rows - 1,
    dc + cols - 1, i, j] is u_i (m) at the centre of the cell at offset (dr, dc) (position
    (dc spacing, dr spacing): rows along Y, cols along X) per newton of f_j spread over the
    spacing x spacing cell at the origin. Half-space: exact closed-form cell integrals of
    the Boussinesq-Cerruti kernel. Layer: the same plus the layer's smooth correction;
    exactly zero beyond LAYER_CUTOFF_RHO thicknesses. Cached: returns a read-only array.
    A layer thinner than a quarter of the spacing is a ValueError (:func:`check_layer_resolved`).
    """
    if not isinstance(elastomer, Elastomer):
        raise TypeError("elastomer must be an Elastomer")
    _check_grid(spacing, rows, cols)
    check_layer_resolved(elastomer, spacing)
    return _cell_kernel_cached(elastomer, float(spacing), int(rows), int(cols))


# --------------------------------------------------------------------------- convolution


@functools.lru_cache(maxsize=4)
def _kernel_fft(elastomer: Elastomer, spacing: float, ny: int, nx: int
                ) -> tuple[np.ndarray, tuple[int, int]]:
    K = cell_kernel(elastomer, spacing, ny, nx)
    shape = (sfft.next_fast_len(2 * ny - 1, real=True), sfft.next_fast_len(2 * nx - 1, real=True))
    Kf = sfft.rfft2(np.moveaxis(K, (2, 3), (0, 1)), s=shape, axes=(-2, -1), workers=-1)
    return Kf, shape


def surface_displacement(elastomer: Elastomer, traction: np.ndarray, spacing: float
                         ) -> np.ndarray:
    """Surface displacement (ny, nx, 3) m of a traction field (ny, nx, 3) Pa on a regular grid.

    Pad frame; traction = force per area the object exerts on the pad, constant over each
    spacing x spacing cell centred on its sample. Linear convolution with :func:`cell_kernel`
    by FFT (no wrap-around: the padded size is at least the kernel's, and every needed
    output index stays inside it); the kernel's transform is cached per (pad, spacing, shape).
    """
    q = np.asarray(traction, dtype=np.float64)
    if q.ndim != 3 or q.shape[2] != 3 or q.shape[0] < 1 or q.shape[1] < 1:
        raise ValueError(f"traction must have shape (ny, nx, 3), got {q.shape}")
    if not np.isfinite(q).all():
        raise ValueError("traction has non-finite values")
    _check_grid(spacing, q.shape[0], q.shape[1])
    ny, nx = q.shape[:2]
    Kf, shape = _kernel_fft(elastomer, float(spacing), ny, nx)
    force = np.moveaxis(q, 2, 0) * (spacing * spacing)
    Ff = sfft.rfft2(force, s=shape, axes=(-2, -1), workers=-1)
    Uf = np.einsum("ijab,jab->iab", Kf, Ff)
    u = sfft.irfft2(Uf, s=shape, axes=(-2, -1), workers=-1)
    return np.ascontiguousarray(np.moveaxis(u[:, ny - 1:2 * ny - 1, nx - 1:2 * nx - 1], 0, 2))
