"""The inversion recovers known loads from displacements of an independent forward model.

Displacements come from :func:`tactile_sl_common.elasticity.surface_displacement` of
continuous Hertz tractions on a 10x finer grid (not from the cell kernel the inversion
uses), sampled at the cell centres, with noise: 3 um on the half-space; 0.5 um on the
2 mm layer, which is so stiff in the normal direction (nearly incompressible, thin) that
3 um of noise alone is worth about 20 mN of normal force (docs/touch.md).
"""
import numpy as np
import pytest

from tactile_sl_common.elasticity import Elastomer, surface_displacement
from tactile_sl_decoder.touch.traction import TractionParams, TractionSolver, _band_rows

PITCH = 5e-4
SHAPE = (22, 20)
SUB = 10


def _displacement(elastomer, loads, noise, rng):
    """Cell-centre displacements of Hertz-profile loads [(fx, fy, fz, a, x0, y0)]."""
    sp = PITCH / SUB
    ny, nx = (SHAPE[0] + 1) * SUB + 1, (SHAPE[1] + 1) * SUB + 1
    x = (np.arange(nx) - (nx - 1) / 2) * sp
    y = (np.arange(ny) - (ny - 1) / 2) * sp
    xx, yy = np.meshgrid(x, y)
    traction = np.zeros(xx.shape + (3,))
    for fx, fy, fz, a, x0, y0 in loads:
        profile = np.sqrt(np.clip(1 - ((xx - x0) ** 2 + (yy - y0) ** 2) / a**2, 0, None))
        profile /= profile.sum() * sp * sp
        traction += profile[..., None] * np.array([fx, fy, fz])
    u = surface_displacement(elastomer, traction, sp)
    cells = u[SUB:SUB + (SHAPE[0] - 1) * SUB + 1:SUB, SUB:SUB + (SHAPE[1] - 1) * SUB + 1:SUB]
    assert cells.shape[:2] == SHAPE
    return cells.reshape(-1, 3) + rng.normal(0.0, noise, (SHAPE[0] * SHAPE[1], 3))


@pytest.fixture(scope="module", params=[0.0, 0.002], ids=["half-space", "layer-2mm"])
def solver(request):
    elastomer = Elastomer(3e5, 0.49, request.param)
    noise = 3e-6 if request.param == 0 else 0.5e-6
    return elastomer, TractionSolver(elastomer, PITCH, SHAPE,
                                     np.arange(SHAPE[0] * SHAPE[1])), noise


@pytest.mark.parametrize("load", [
    (0.0, 0.0, -0.05, 1.0e-3, 3e-4, -2e-4),
    (0.0, 0.0, -0.5, 2.0e-3, -5e-4, 4e-4),
    (0.1, -0.05, -0.8, 2.0e-3, 1e-3, 1e-3),
])
def test_resultant_of_a_known_load(solver, load):
    elastomer, s, noise = solver
    u = _displacement(elastomer, [load], noise, np.random.default_rng(3))
    forces, wrench = s.solve(u, np.ones(len(u), bool))
    fx, fy, fz, _a, x0, y0 = load
    assert abs(wrench[2] - fz) < 0.03 * abs(fz) + 3e-3
    for axis, true in ((0, fx), (1, fy)):
        assert abs(wrench[axis] - true) < 0.05 * abs(fz) + 3e-3
    # the centroid (My, -Mx) / P within 0.1 mm (+ 2 mN at 1 mm of lever)
    assert abs(wrench[3] - y0 * fz) < 1e-4 * abs(fz) + 2e-6     # Mx = y fz
    assert abs(wrench[4] + x0 * fz) < 1e-4 * abs(fz) + 2e-6     # My = -x fz
    # per-cell map: non-negative pressure, sums to the resultant, centred on the load
    assert (forces[:, 2] <= 0).all()
    assert np.allclose(forces.sum(axis=0), wrench[:3], atol=1e-9)


def test_untouched_pad_gives_almost_nothing(solver):
    elastomer, s, noise = solver
    u = _displacement(elastomer, [], noise, np.random.default_rng(5))
    _forces, wrench = s.solve(u, np.ones(len(u), bool))
    assert abs(wrench[2]) < 5e-3


def test_missing_cells_are_tolerated(solver):
    elastomer, s, noise = solver
    rng = np.random.default_rng(9)
    u = _displacement(elastomer, [(0.0, 0.0, -0.5, 2e-3, 0.0, 0.0)], noise, rng)
    valid = rng.random(len(u)) > 0.05
    u[~valid] = 1.0                     # garbage where nothing was decoded: must be ignored
    _forces, wrench = s.solve(u, valid)
    assert abs(wrench[2] + 0.5) < 0.03 * 0.5


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="map_weight"):
        TractionParams(map_weight=0.0).validate()
    with pytest.raises(ValueError, match="support_fraction"):
        TractionParams(support_fraction=1.5).validate()


@pytest.mark.parametrize("seed", range(4))
def test_band_rows_give_the_band_products_bits(seed):
    """The shear rows of the contact alone equal those of the band product, bit for bit (the
    points and touch digests depend on it; a BLAS that computes otherwise falls back)."""
    rng = np.random.default_rng(seed)
    matrix = rng.standard_normal((300, 900)).astype(np.float32)
    for _ in range(40):
        vector = rng.standard_normal(900).astype(np.float32)
        start = int(rng.integers(0, 290))
        stop = int(rng.integers(start + 1, 301))
        rows = np.flatnonzero(rng.random(stop - start) < rng.uniform(0.05, 0.9))
        np.testing.assert_array_equal(_band_rows(matrix, start, stop, rows, vector),
                                      (matrix[start:stop] @ vector)[rows])
