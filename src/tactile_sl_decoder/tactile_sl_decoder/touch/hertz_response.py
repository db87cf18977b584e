"""The pad's surface response to Hertz-profile tractions, tabulated in the distance (no rclpy).

The slip estimator (:mod:`.slip`) fits a contact's measured displacement field with the
response to Hertz-shaped tractions w_s(r) = sqrt(1 - r^2 / s^2) (unit peak, zero beyond
r = s) of several radii s.  Both the pressure and every term of Mindlin's partial-slip
traction have that shape, and the response of an axisymmetric profile depends on the
distance r to its centre and on the angle theta only through cos theta, cos 2 theta and
sin 2 theta, so four radial functions per radius describe it (pad frame, G the shear
modulus; derived from the Fourier-domain compliance of
:func:`tactile_sl_common.elasticity.fourier_compliance` by the angular integrals of
Gradshteyn-Ryzhik 8.411.1):

* normal traction q_z = w_s:      u_r = C_s(r),  u_z = D_s(r);
* tangential traction q_x = w_s:  u_x = A_s(r) - B_s(r) cos 2 theta,
  u_y = -B_s(r) sin 2 theta,  u_z = -C_s(r) cos theta  (along any direction by rotation),

with A = 1/(2 pi G) int W_s(k) (L + T)/2 J0(k r) dk, B = ... (L - T)/2 J2, C = ... Q J1,
D = ... Z J0, where W_s(k) = 2 pi s^2 (sin t - t cos t) / t^3 (t = k s) is the Hankel
transform of w_s and L, T, Z, Q the compliances of
:func:`tactile_sl_common.elasticity.layer_compliance`.

* **Half-space** (L = Z = 1 - nu, T = 1, Q = (1 - 2 nu)/2): A = (2 - nu)/2 H0,
  B = -nu/2 H2, C = (1 - 2 nu)/2 H1, D = (1 - nu) H0, times s / (2 pi G), with the closed
  forms in rho = r / s of K.L. Johnson, Contact Mechanics, 1985, eqs. 3.41-3.42 (the
  displacements under Hertz pressure): H0 = pi^2 (2 - rho^2) / 4 inside,
  pi/2 [(2 - rho^2) asin(1/rho) + rho sqrt(1 - 1/rho^2)] outside; H1 = 2 pi / (3 rho)
  [1 - (1 - rho^2)^(3/2)] inside, 2 pi / (3 rho) outside; and H2 = 2/rho^2 int_0^rho t H0 dt
  - H0 (from J2(x) = 2 J1(x)/x - J0(x)), which is pi^2 rho^2 / 8 inside (Johnson's u_x
  under q0 sqrt(1 - r^2/a^2), section 3.7) and closed form outside (see :func:`_h2`).
* **Layer** (``thickness`` h > 0): the half-space part plus the integrals of the layer's
  differences, which decay as (k h)^2 e^(-2 k h), over k h <= HALF_SPACE_KH by
  Gauss-Legendre quadrature (as the elasticity module's layer kernel).

The tables agree with the cell-kernel convolution the simulator renders with
(:func:`tactile_sl_common.elasticity.surface_displacement`) to about 1e-3 (tests).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from scipy import special

from tactile_sl_common.elasticity import (
    Elastomer,
    layer_compliance,
    layer_quadrature,
)

FUNCTIONS = ("A", "B", "C", "D")
"""The four radial functions of a table, in order (see the module docstring)."""


def _h0(rho: np.ndarray) -> np.ndarray:
    """Int W_1(k) J0(k rho) dk (Johnson 1985 eq. 3.41a inside, 3.42a outside)."""
    out = np.empty_like(rho)
    inside = rho <= 1.0
    ri, ro = rho[inside], rho[~inside]
    out[inside] = np.pi ** 2 * (2.0 - ri * ri) / 4.0
    out[~inside] = np.pi / 2.0 * ((2.0 - ro * ro) * np.arcsin(1.0 / ro)
                                  + ro * np.sqrt(1.0 - 1.0 / (ro * ro)))
    return out


def _h1(rho: np.ndarray) -> np.ndarray:
    """Int W_1(k) J1(k rho) dk (Johnson 1985 eq. 3.41b: the radial displacement)."""
    out = np.empty_like(rho)
    inside = rho <= 1.0
    ri = np.maximum(rho[inside], 1e-12)
    out[inside] = 2.0 * np.pi / (3.0 * ri) * (1.0 - (1.0 - ri * ri) ** 1.5)
    out[~inside] = 2.0 * np.pi / (3.0 * rho[~inside])
    return out


def _h2(rho: np.ndarray) -> np.ndarray:
    """Int W_1(k) J2(k rho) dk = 2/rho^2 int_0^rho t H0(t) dt - H0(rho).

    Inside pi^2 rho^2 / 8; outside, with the integral of H0 in closed form (integration by
    parts of Johnson's eq. 3.42a): int_0^rho t H0 dt = pi/2 [(rho^2 - rho^4/4) asin(1/rho)
    + 3/4 sqrt(rho^2 - 1) + (rho^2 - 1)^(3/2) / 4].
    """
    out = np.empty_like(rho)
    inside = rho <= 1.0
    out[inside] = np.pi ** 2 * rho[inside] ** 2 / 8.0
    ro = rho[~inside]
    root = np.sqrt(ro * ro - 1.0)
    integral = np.pi / 2.0 * ((ro * ro - ro ** 4 / 4.0) * np.arcsin(1.0 / ro)
                              + 0.75 * root + root ** 3 / 4.0)
    out[~inside] = 2.0 / (ro * ro) * integral - _h0(ro)
    return out


def half_space_functions(elastomer: Elastomer, radius: float, r: np.ndarray) -> np.ndarray:
    """(4, len(r)) A, B, C, D of a half-space for a Hertz profile of ``radius`` (m/Pa)."""
    rho = np.asarray(r, np.float64) / radius
    nu = elastomer.poisson_ratio
    scale = radius / (2.0 * np.pi * elastomer.shear_modulus)
    h0, h1, h2 = _h0(rho), _h1(rho), _h2(rho)
    return scale * np.stack([(2.0 - nu) / 2.0 * h0, -nu / 2.0 * h2,
                             (1.0 - 2.0 * nu) / 2.0 * h1, (1.0 - nu) * h0])


def layer_corrections(elastomer: Elastomer, radii: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(len(radii), 4, len(r)) layer-minus-half-space A, B, C, D (zero for a half-space)."""
    radii = np.asarray(radii, np.float64)
    r = np.asarray(r, np.float64)
    h, nu, mu = elastomer.thickness, elastomer.poisson_ratio, elastomer.shear_modulus
    if h <= 0:
        return np.zeros((len(radii), 4, len(r)))
    t, w = layer_quadrature()
    L, T, Z, Q = layer_compliance(t, nu)
    k = t / h
    ts = k[:, None] * radii[None, :]
    small = ts < 1e-2   # series of (sin t - t cos t) / t^3 = 1/3 - t^2/30 + ...
    safe = np.where(small, 1.0, ts)
    shape = np.where(small, 1.0 / 3.0 - ts * ts / 30.0,
                     (np.sin(safe) - safe * np.cos(safe)) / safe ** 3)
    transform = 2.0 * np.pi * radii[None, :] ** 2 * shape * (w / h)[:, None] / (2 * np.pi * mu)
    arg = r[:, None] * k[None, :]
    j0, j1 = special.j0(arg), special.j1(arg)
    with np.errstate(divide="ignore", invalid="ignore"):     # J2 = 2 J1(x) / x - J0(x)
        j2 = np.where(arg > 1e-8, 2 * j1 / np.where(arg > 0, arg, 1.0) - j0, arg ** 2 / 8)
    out = np.stack([(j0 * ((L + T) / 2 - (2 - nu) / 2)) @ transform,
                    (j2 * ((L - T) / 2 + nu / 2)) @ transform,
                    (j1 * (Q - (1 - 2 * nu) / 2)) @ transform,
                    (j0 * (Z - (1 - nu))) @ transform])       # (4, len(r), len(radii))
    return np.ascontiguousarray(out.transpose(2, 0, 1))


@dataclass(frozen=True)
class HertzResponse:
    """Radial response tables of unit-peak Hertz profiles of radii s_j = j ``step``.

    ``tables[j, f, i]`` is function f (A, B, C, D; m/Pa) of radius s_j at distance
    i ``dr``; s_0 = 0 carries no traction (all zero).  Beyond the last distance a lookup
    takes the last value (the estimator keeps its window inside).
    """

    elastomer: Elastomer
    step: float
    dr: float
    tables: np.ndarray
    _pairs: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # value and slope to the next distance as one complex number per entry, so that a
        # lookup is a single gather (the estimate's hot path)
        nxt = np.concatenate([self.tables[:, :, 1:], self.tables[:, :, -1:]], axis=2)
        pairs = (self.tables + 1j * (nxt - self.tables)).reshape(-1)
        pairs.setflags(write=False)
        object.__setattr__(self, "_pairs", pairs)

    @property
    def radii(self) -> np.ndarray:
        return self.step * np.arange(self.tables.shape[0])

    @property
    def max_distance(self) -> float:
        return self.dr * (self.tables.shape[2] - 1)

    def sample(self, r: np.ndarray, radii: np.ndarray | slice) -> np.ndarray:
        """(n, 4, len(r)) functions of the table radii ``radii`` (indices) at distances ``r``.

        Linear between table distances (the functions are smooth but for a kink of the
        derivative at r = s).
        """
        n, _, nr = self.tables.shape
        x = np.clip(np.asarray(r, np.float64) / self.dr, 0.0, nr - 1.000001)
        i = x.astype(np.intp)
        f = x - i
        rows = (np.arange(n * 4).reshape(n, 4)[radii] * nr).reshape(-1, 1)
        got = self._pairs[rows + i]               # (n' * 4, M): value + 1j slope
        out = got.real + got.imag * f
        return out.reshape(-1, 4, len(i))


@functools.lru_cache(maxsize=8)
def hertz_response(elastomer: Elastomer, step: float, max_radius: float,
                   max_distance: float) -> HertzResponse:
    """The tables of an elastomer (cached: built once per pad and grid, ~50 ms for a layer)."""
    if not (step > 0 and max_radius >= step and max_distance > 0):
        raise ValueError(f"need step > 0, max_radius >= step and max_distance > 0, got "
                         f"{step}, {max_radius}, {max_distance}")
    n = int(np.ceil(max_radius / step)) + 1
    dr = step / 8.0
    r = dr * np.arange(int(np.ceil(max_distance / dr)) + 2)
    radii = step * np.arange(n)
    tables = np.zeros((n, 4, len(r)))
    for j in range(1, n):
        tables[j] = half_space_functions(elastomer, float(radii[j]), r)
    tables[1:] += layer_corrections(elastomer, radii[1:], r)
    tables.setflags(write=False)
    return HertzResponse(elastomer, float(step), float(dr), tables)
