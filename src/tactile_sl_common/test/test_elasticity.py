"""The elastic surface kernels against closed forms (Johnson 1985) and their own limits."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import special

from tactile_sl_common.elasticity import (
    Elastomer,
    cell_kernel,
    check_layer_resolved,
    fourier_compliance,
    layer_compliance,
    point_green,
    surface_displacement,
)

E, NU = 3.0e5, 0.49
HALF = Elastomer(E, NU, 0.0)


def disc_grid(a: float, n_per_a: int, extent: float) -> tuple[np.ndarray, np.ndarray, float]:
    s = a / n_per_a
    n = int(round(extent * a / s))
    c = (np.arange(2 * n + 1) - n) * s
    X, Y = np.meshgrid(c, c)
    return X, Y, s


@pytest.mark.parametrize("h", [0.0, 0.002])
def test_reciprocity(h: float) -> None:
    # Betti: u_i at x from f_j at 0 = u_j at 0 from f_i at x, i.e. K_ij(d) = K_ji(-d)
    K = cell_kernel(Elastomer(E, 0.3, h), 0.0005, 6, 5)
    assert np.allclose(K, np.transpose(K[::-1, ::-1], (0, 1, 3, 2)), rtol=0,
                       atol=1e-12 * np.abs(K).max())
    x, y = np.array([0.001, -0.0007]), np.array([0.0004, 0.002])
    G = point_green(HALF, x, y)
    assert np.allclose(G, np.transpose(point_green(HALF, -x, -y), (0, 2, 1)))


def test_signs_pad_frame() -> None:
    K = cell_kernel(HALF, 0.0005, 3, 3)
    c = (2, 2)
    assert K[c][2, 2] > 0  # f_z < 0 (pressing) gives u_z < 0 (indentation)
    assert K[c][0, 0] > 0 and K[c][1, 1] > 0  # a push drags the surface along
    # a tangential push +x depresses the surface ahead (x > 0) and raises it behind
    assert K[2, 3][2, 0] < 0 < K[2, 1][2, 0]
    # pressing in pulls neighbours towards the load: u_x < 0 at x > 0 for f_z < 0
    assert K[2, 3][0, 2] > 0
    # self cell of 1/r over a square: 4 s ln(1 + sqrt 2) / s^2 (closed form)
    s = 0.0005
    expected = (1 - NU**2) / (np.pi * E) * 4 * np.log(1 + np.sqrt(2)) / s
    assert K[c][2, 2] == pytest.approx(expected, rel=1e-12)


def test_cell_kernel_far_cells_match_point_kernel() -> None:
    K = cell_kernel(HALF, 0.0005, 40, 40)
    G = point_green(HALF, np.array(30 * 0.0005), np.array(20 * 0.0005))
    assert np.allclose(K[39 + 20, 39 + 30], G, rtol=2e-4)


def test_hertz_pressure_half_space() -> None:
    # Johnson 1985 eq. 3.41 (inside) and 3.42 (outside) for p = p0 sqrt(1 - r^2/a^2)
    a, p0 = 0.001, 1.0e4
    X, Y, s = disc_grid(a, 25, 3.0)
    r = np.hypot(X, Y)
    q = np.zeros(X.shape + (3,))
    q[..., 2] = -p0 * np.sqrt(np.clip(1 - (r / a) ** 2, 0, None))
    u = surface_displacement(HALF, q, s)
    k = (1 - NU**2) / E
    inside = r < a
    rr = np.maximum(r, a)
    expected = np.where(inside, k * np.pi * p0 * (2 * a * a - r * r) / (4 * a),
                        k * p0 / (2 * a) * ((2 * a * a - rr * rr) * np.arcsin(a / rr)
                                            + a * np.sqrt(rr * rr - a * a)))
    uz0 = k * np.pi * p0 * a / 2
    assert np.abs(-u[..., 2] - expected).max() < 0.01 * uz0
    # radial displacement inside, Johnson eq. 3.41b:
    # u_r = -(1-2nu)(1+nu) a^2 p0 / (3 E r) [1 - (1 - r^2/a^2)^1.5]
    ring = inside & (r > 0.3 * a)
    rr, Xr, Yr = r[ring], X[ring], Y[ring]
    ur = (u[..., 0][ring] * Xr + u[..., 1][ring] * Yr) / rr
    ur_exp = -(1 - 2 * NU) * (1 + NU) * a * a * p0 / (3 * E * rr) * (1 - (1 - (rr / a) ** 2) ** 1.5)
    assert np.abs(ur - ur_exp).max() < 0.02 * np.abs(ur_exp).max()


def test_uniform_pressure_disc_half_space() -> None:
    # Johnson 1985 eq. 3.32: centre deflection 2 (1 - nu^2) p a / E; edge 4 (1 - nu^2) p a / (pi E)
    a, p = 0.001, 2.0e3
    X, Y, s = disc_grid(a, 40, 1.2)
    r = np.hypot(X, Y)
    q = np.zeros(X.shape + (3,))
    q[..., 2] = np.where(r <= a, -p, 0.0)
    u = surface_displacement(HALF, q, s)
    n = X.shape[0] // 2
    assert -u[n, n, 2] == pytest.approx(2 * (1 - NU**2) * p * a / E, rel=0.01)
    assert -u[n, n + 40, 2] == pytest.approx(4 * (1 - NU**2) * p * a / (np.pi * E), rel=0.02)


def test_layer_compliance_limits() -> None:
    nu = 0.3
    t = np.array([1e-6, 1e-4])
    L, T, Z, Q = layer_compliance(t, nu)
    # k -> 0: u_t = q h / mu, u_z = p h (1 - 2 nu) / (2 mu (1 - nu)); compliance x (mu k) / t
    assert np.allclose(L / t, 1.0, rtol=1e-6)
    assert np.allclose(T / t, 1.0, rtol=1e-6)
    assert np.allclose(Z / t, (1 - 2 * nu) / (2 * (1 - nu)), rtol=1e-6)
    assert np.all(np.abs(Q) < 1e-3)
    # h -> infinity: the half-space, Z = (1 - nu) i.e. u_z^ = 2 (1 - nu^2) p^ / (E k)
    t = np.array([5.0, 8.0, 12.0, 14.9])
    L, T, Z, Q = layer_compliance(t, nu)
    bound = 10 * t * t * np.exp(-2 * t)
    assert np.all(np.abs(Z - (1 - nu)) < bound) and np.all(np.abs(L - (1 - nu)) < bound)
    assert np.all(np.abs(Q - (1 - 2 * nu) / 2) < bound) and np.all(np.abs(T - 1) < bound)
    el = Elastomer(E, nu, 0.0)
    C = fourier_compliance(el, np.array([300.0]), np.array([400.0]))[0]
    assert C[2, 2].real == pytest.approx(2 * (1 - nu**2) / (E * 500.0), rel=1e-12)
    C0 = fourier_compliance(Elastomer(E, nu, 0.002), np.array([0.0]), np.array([0.0]))[0]
    mu = el.shear_modulus
    assert C0[0, 0] == pytest.approx(0.002 / mu)
    assert C0[2, 2] == pytest.approx(0.002 * (1 - 2 * nu) / (2 * mu * (1 - nu)))


def test_layer_kernel_tends_to_half_space() -> None:
    s = 0.0005
    Kh = cell_kernel(Elastomer(E, 0.3, 0.0), s, 4, 4)
    Kl = cell_kernel(Elastomer(E, 0.3, 2.0), s, 4, 4)  # h = 4000 cells
    assert np.allclose(Kl, Kh, rtol=0, atol=2e-3 * np.abs(Kh).max())


@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_layer_uniform_load_is_uniaxial(nu: float) -> None:
    # a load much wider than the layer: u = q h / mu, p h (1 - 2 nu) / (2 mu (1 - nu))
    h, s = 0.0005, 0.00025
    el = Elastomer(E, nu, h)
    q = np.zeros((101, 101, 3))
    q[..., 0], q[..., 2] = 300.0, -1000.0
    u = surface_displacement(el, q, s)[50, 50]
    mu = el.shear_modulus
    assert u[0] == pytest.approx(300.0 * h / mu, rel=1e-3)
    assert u[2] == pytest.approx(-1000.0 * h * (1 - 2 * nu) / (2 * mu * (1 - nu)), rel=2e-3)


def test_layer_gaussian_load_against_hankel_quadrature() -> None:
    # independent route: axisymmetric Gaussian traction, u from 1-D Hankel integrals of the
    # Fourier compliance (Gradshteyn-Ryzhik 8.411.1) vs the real-space kernel convolution
    h, sigma, nu = 0.001, 0.0005, 0.45
    el = Elastomer(E, nu, h)
    mu = el.shear_modulus
    X, Y, s = disc_grid(sigma, 10, 7.0)
    g = np.exp(-(X * X + Y * Y) / (2 * sigma**2)) / (2 * np.pi * sigma**2)
    q = np.zeros(X.shape + (3,))
    q[..., 0], q[..., 2] = 0.2 * g, -1.0 * g  # 0.2 N along x, 1 N pressing
    u = surface_displacement(el, q, s)
    k = np.linspace(1e-9, 15 / h, 200001)
    dk = k[1] - k[0]
    L, T, Z, Q = layer_compliance(k * h, nu)
    qhat = np.exp(-((k * sigma) ** 2) / 2)
    n = X.shape[0] // 2
    uz0 = np.sum(Z * qhat) * dk / (2 * np.pi * mu) * -1.0
    ux0 = np.sum((L + T) / 2 * qhat) * dk / (2 * np.pi * mu) * 0.2
    assert u[n, n, 2] == pytest.approx(uz0, rel=3e-3)
    assert u[n, n, 0] == pytest.approx(ux0, rel=3e-3)
    x0 = 10 * s  # u_z at (x0, 0) from the tangential load: -(1/2 pi mu) int Q J1(k x0) q^ dk
    uzx = -np.sum(Q * special.j1(k * x0) * qhat) * dk / (2 * np.pi * mu) * 0.2
    uzz = np.sum(Z * special.j0(k * x0) * qhat) * dk / (2 * np.pi * mu) * -1.0
    assert u[n, n + 10, 2] == pytest.approx(uzx + uzz, rel=3e-3)


def test_surface_displacement_is_linear_convolution() -> None:
    el = Elastomer(E, NU, 0.001)
    rng = np.random.default_rng(1)
    q = rng.normal(size=(7, 9, 3))
    u = surface_displacement(el, q, 0.0004)
    K = cell_kernel(el, 0.0004, 7, 9)
    f = q * 0.0004**2
    direct = np.zeros_like(u)
    for r in range(7):
        for c in range(9):
            sub = K[r - np.arange(7)[:, None] + 6, c - np.arange(9)[None, :] + 8]
            direct[r, c] = np.einsum("abij,abj->i", sub, f)
    assert np.allclose(u, direct, rtol=1e-9, atol=1e-12 * np.abs(direct).max())


@pytest.mark.parametrize("kwargs, message", [
    ({"youngs_modulus": 0.0, "poisson_ratio": 0.4}, "youngs_modulus"),
    ({"youngs_modulus": float("nan"), "poisson_ratio": 0.4}, "youngs_modulus"),
    ({"youngs_modulus": 1e5, "poisson_ratio": 0.6}, "poisson_ratio"),
    ({"youngs_modulus": 1e5, "poisson_ratio": -0.1}, "poisson_ratio"),
    ({"youngs_modulus": 1e5, "poisson_ratio": 0.4, "thickness": -1e-3}, "thickness"),
    ({"youngs_modulus": 1e5, "poisson_ratio": 0.4, "thickness": float("inf")}, "thickness"),
])
def test_bad_elastomer(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Elastomer(**kwargs)


def test_bad_grid_input() -> None:
    with pytest.raises(ValueError, match="spacing"):
        cell_kernel(HALF, 0.0, 3, 3)
    with pytest.raises(ValueError, match="rows"):
        cell_kernel(HALF, 0.001, 0, 3)
    with pytest.raises(ValueError, match="shape"):
        surface_displacement(HALF, np.zeros((4, 4, 2)), 0.001)
    with pytest.raises(ValueError, match="non-finite"):
        surface_displacement(HALF, np.full((4, 4, 3), np.nan), 0.001)
    assert Elastomer(E, NU).shear_modulus == pytest.approx(E / (2 * (1 + NU)))


def test_a_layer_thinner_than_a_quarter_cell_is_refused() -> None:
    """Issue 28, item 3: 10 um on a 0.5 mm pitch zeroed the whole kernel (the inversion then
    failed with a LinAlgError), 20 um was 14x too compliant; both are now a clear error."""
    s = 0.0005
    for h in (1e-5, 2e-5, 0.2 * s):
        with pytest.raises(ValueError, match="quarter of the cell pitch"):
            cell_kernel(Elastomer(E, NU, h), s, 3, 3)
    K = cell_kernel(Elastomer(E, NU, 0.25 * s), s, 3, 3)     # the thinnest resolved layer
    assert np.isfinite(K).all() and K[2, 2, 2, 2] > 0
    check_layer_resolved(HALF, s)
