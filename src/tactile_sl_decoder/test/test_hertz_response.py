"""Radial response tables of Hertz-profile tractions against the simulator's convolution."""
import math

import numpy as np
import pytest

from tactile_sl_common.elasticity import Elastomer, surface_displacement
from tactile_sl_decoder.touch.hertz_response import (
    half_space_functions,
    hertz_response,
    layer_corrections,
)

SPACING, N = 2e-5, 601       # a 12 mm square grid, the profile centred on its middle node
RADIUS = 2e-3


def _convolved(elastomer: Elastomer, axis: int) -> np.ndarray:
    """Surface displacement (N, N, 3) of the unit-peak profile along ``axis`` (0 x, 2 z)."""
    xs = (np.arange(N) - (N - 1) / 2) * SPACING
    X, Y = np.meshgrid(xs, xs)
    q = np.zeros((N, N, 3))
    q[..., axis] = np.sqrt(np.clip(1.0 - (X * X + Y * Y) / RADIUS ** 2, 0.0, None))
    return surface_displacement(elastomer, q, SPACING)


def _functions(elastomer: Elastomer, r: np.ndarray) -> np.ndarray:
    out = half_space_functions(elastomer, RADIUS, r)
    return out + layer_corrections(elastomer, np.array([RADIUS]), r)[0]


@pytest.mark.parametrize("elastomer", [Elastomer(3e5, 0.49, 0.0), Elastomer(3e5, 0.3, 0.0),
                                       Elastomer(3e5, 0.49, 0.002)])
def test_tables_match_the_cell_kernel_convolution(elastomer):
    """Along x (theta = 0) and y (theta = 90 deg): u_x = A -+ B, u_z = -C (tangential load),
    u_r = C and u_z = D (normal load), to 0.5 % of the largest value."""
    c = (N - 1) // 2
    steps = np.array([0, 20, 50, 90, 100, 110, 150, 220, 290])
    r = steps * SPACING
    A, B, C, D = _functions(elastomer, r)
    tangential, normal = _convolved(elastomer, 0), _convolved(elastomer, 2)
    scale = np.abs(tangential).max()
    assert np.abs(tangential[c, c + steps, 0] - (A - B)).max() < 5e-3 * scale
    assert np.abs(tangential[c + steps, c, 0] - (A + B)).max() < 5e-3 * scale
    assert np.abs(tangential[c, c + steps, 2] + C).max() < 5e-3 * scale
    assert np.abs(tangential[c + steps, c, 1]).max() < 5e-3 * scale
    scale = np.abs(normal).max()
    assert np.abs(normal[c, c + steps, 2] - D).max() < 5e-3 * scale
    assert np.abs(normal[c, c + steps, 0] - C).max() < 5e-3 * scale
    # off the axes: u_y = -B sin 2 theta under a tangential load (Cerruti's coupling)
    k = 70
    B45 = _functions(elastomer, np.array([k * SPACING * math.sqrt(2)]))[1, 0]
    assert tangential[c + k, c + k, 1] == pytest.approx(-B45, abs=5e-3 * np.abs(
        tangential).max())


def test_half_space_closed_forms():
    """Johnson 1985 eq. 3.41: u_z = (1 - nu^2) pi p0 (2 a^2 - r^2) / (4 a E) inside."""
    e = Elastomer(3e5, 0.4, 0.0)
    r = np.array([0.0, 0.5e-3, 1.5e-3])
    D = half_space_functions(e, RADIUS, r)[3]
    expected = (1 - 0.4 ** 2) * math.pi * (2 * RADIUS ** 2 - r ** 2) / (4 * RADIUS * 3e5)
    assert D == pytest.approx(expected, rel=1e-12)
    # continuous at the rim, and the far field of a point force 2 pi a^2 / 3 (1/r)
    rim = half_space_functions(e, RADIUS, np.array([RADIUS * (1 - 1e-9), RADIUS * (1 + 1e-9)]))
    assert rim[:, 0] == pytest.approx(rim[:, 1], rel=1e-6)
    far = 50 * RADIUS
    force = 2 * math.pi * RADIUS ** 2 / 3
    boussinesq = (1 - 0.4 ** 2) * force / (math.pi * 3e5 * far)
    assert half_space_functions(e, RADIUS, np.array([far]))[3, 0] == pytest.approx(
        boussinesq, rel=1e-3)


def test_table_lookup_is_linear_between_distances_and_cached():
    e = Elastomer(3e5, 0.49, 0.0)
    table = hertz_response(e, 1.25e-4, 4e-3, 8e-3)
    assert table is hertz_response(e, 1.25e-4, 4e-3, 8e-3)
    assert np.all(table.tables[0] == 0.0) and table.radii[3] == pytest.approx(3.75e-4)
    r = np.array([0.0, 1.0e-3, 2.345e-3])
    got = table.sample(r, np.array([8, 16]))
    for k, j in enumerate((8, 16)):
        exact = half_space_functions(e, j * 1.25e-4, r)
        assert np.abs(got[k] - exact).max() < 1e-4 * np.abs(exact).max()
    far = table.sample(np.array([1.0]), np.array([8]))       # beyond the table: the last value
    assert np.allclose(far[0, :, 0], table.tables[8, :, -1], rtol=1e-5, atol=0)
    with pytest.raises(ValueError, match="step"):
        hertz_response(e, 0.0, 4e-3, 8e-3)
