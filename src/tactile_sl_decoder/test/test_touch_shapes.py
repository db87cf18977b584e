"""Contact area and largest indentation for indenters that are not spheres (issue 25).

The pressures of the simulator's load contacts (a sphere's Hertz pressure, a rigid flat
punch's, infinite at its rim, a cylinder lying on the pad, and two contacts at once) are
pushed through the elastic half-space on a 10x finer grid than the cells
(:func:`tactile_sl_common.elasticity.surface_displacement`, not the cell kernel the stage
inverts), sampled at the cell centres with the decoder's noise (0.75 um across, 2.5 um along
the depth), and given to the touch stage.  The truth is the simulator's (area where the
traction presses, largest indentation of the fine grid).  Before issue 25 the area came from
a threshold calibrated on spheres: a flat punch's was 100 % too large.
"""
import cv2
import numpy as np
import pytest
from test_touch_stage import _points
from test_touch_traction import PITCH, SHAPE

from tactile_sl_common.elasticity import Elastomer, surface_displacement
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.stage import TouchStage
from tactile_sl_decoder.touch.support import constrained_edge
from tactile_sl_sim.loads import LoadContact, touch_truth

SUB = 10
HALF = Elastomer(3e5, 0.49, 0.0)
NOISE = np.array([0.75e-6, 0.75e-6, 2.5e-6])


def _field(loads):
    """Cell-centre displacements (N, 3) of load contacts, and the simulator's truth."""
    sp = PITCH / SUB
    ny, nx = (SHAPE[0] + 1) * SUB + 1, (SHAPE[1] + 1) * SUB + 1
    xs = (np.arange(nx) - (nx - 1) / 2) * sp
    ys = (np.arange(ny) - (ny - 1) / 2) * sp
    X, Y = np.meshgrid(xs, ys)
    traction = sum(load.traction(X, Y, sp * sp) for load in loads)
    u = surface_displacement(HALF, traction, sp)
    cells = u[SUB:SUB + (SHAPE[0] - 1) * SUB + 1:SUB, SUB:SUB + (SHAPE[1] - 1) * SUB + 1:SUB]
    none = np.zeros(0)
    truth = touch_truth(loads, traction, u[..., 2], xs, ys, sp, (none, none),
                        (none, none, np.zeros((0, 3)), np.zeros((0, 3))))
    return cells.reshape(-1, 3), truth


SHAPES = {
    "sphere": [LoadContact(radius=2e-3, x=3e-4, y=-2e-4, force=(0, 0, -0.5))],
    "flat punch": [LoadContact(radius=1.5e-3, profile="punch", x=-4e-4, y=3e-4,
                               force=(0, 0, -0.5))],
    "cylinder": [LoadContact(radius=1.2e-3, profile="cylinder", length=4e-3,
                             angle=np.radians(30), x=2e-4, force=(0, 0, -0.5))],
    "two contacts": [LoadContact(radius=1.8e-3, x=-2.5e-3, y=-1.5e-3, force=(0, 0, -0.4)),
                     LoadContact(radius=1.4e-3, profile="punch", x=2.2e-3, y=2e-3,
                                 force=(0, 0, -0.4))],
}


@pytest.fixture(scope="module")
def stage():
    stage = TouchStage(SensorConfig(HALF), SHAPE, PITCH)
    rng = np.random.default_rng(25)
    stage.update(_points(rng.normal(0.0, NOISE, (SHAPE[0] * SHAPE[1], 3))))
    assert stage.ready
    return stage


@pytest.mark.parametrize("name", list(SHAPES))
def test_area_and_indentation_of_any_indenter(stage, name):
    disp, truth = _field(SHAPES[name])
    rng = np.random.default_rng(len(name))
    out = stage.update(_points(disp + rng.normal(0.0, NOISE, disp.shape)))
    c = out.contact
    assert c.in_contact and len(c.region_area) == len(SHAPES[name])
    assert abs(c.area / truth.area - 1) < 0.15, (c.area, truth.area)
    assert abs(c.max_depth - truth.max_depth) < 10e-6, (c.max_depth, truth.max_depth)


def test_support_pressure_is_non_negative_and_local(stage):
    disp, truth = _field(SHAPES["flat punch"])
    stage.update(_points(disp))
    noise = stage.contact_params.displacement_noise
    p = stage.solver.support_pressure(noise, 2.0, 5.0)
    assert p is not None and np.all(p >= 0)
    # pressing cells lie within the punch (and the cells its rim cuts), and carry its force
    x = (stage.solver.cols - (SHAPE[1] - 1) / 2) * PITCH
    y = (stage.solver.rows - (SHAPE[0] - 1) / 2) * PITCH
    r = np.hypot(x + 4e-4, y - 3e-4)
    pressing = p > 2.0 * noise * stage.solver.support_gain
    assert r[pressing].max() < 1.5e-3 + PITCH
    assert p.sum() == pytest.approx(0.5, rel=0.1)
    # a faint touch cannot locate an edge: no constrained map, the area comes from the map
    faint, _ = _field([LoadContact(radius=4e-3, force=(0, 0, -0.02))])
    stage.update(_points(faint))
    assert stage.solver.support_pressure(noise, 2.0, 5.0) is None


def reference_constrained_edge(free, clear, rows, cols, shape, inverse, cells, max_rounds):
    """The numpy version of :func:`~tactile_sl_decoder.touch.support.constrained_edge`."""
    grid = np.zeros(shape, np.uint8)
    grid[rows[clear], cols[clear]] = 1
    square = np.ones((3, 3), np.uint8)
    edge = (cv2.dilate(grid, square) > 0) & (cv2.erode(grid, square, borderValue=1) == 0)
    ring_at = np.flatnonzero(edge[rows, cols])
    ring = cells[ring_at]
    near = inverse[np.ix_(ring, ring)]
    free_ring = free[ring_at]
    p_ring = free_ring
    held = free_ring < 0.0
    for _ in range(max_rounds):
        at = np.flatnonzero(held)
        if len(at) == 0:
            p_ring = free_ring
            break
        nu = np.linalg.solve(near[np.ix_(at, at)].T, -free_ring[at])
        if (nu < 0.0).any():
            held[at[nu < 0.0]] = False
            continue
        p_ring = free_ring + near[at].T @ nu
        p_ring[at] = 0.0
        more = (p_ring < -1e-12 * np.abs(free_ring).max()) & ~held
        if not more.any():
            break
        held |= more
    p = free.copy()
    p[ring_at] = p_ring
    return p


@pytest.mark.parametrize("name", list(SHAPES))
def test_compiled_constrained_edge_equals_the_numpy_version(stage, name):
    solver = stage.solver
    disp, _ = _field(SHAPES[name])
    rng = np.random.default_rng(7)
    stage.update(_points(disp + rng.normal(0.0, NOISE, disp.shape)))
    u32, window = solver._near
    free = (solver._support_rows[window] @ u32).astype(np.float64)
    noise = stage.contact_params.displacement_noise
    clear = free > 2.0 * noise * solver.support_gain[window]
    args = (free, clear, solver.rows[window], solver.cols[window])
    got = constrained_edge(*args, *SHAPE, solver._support_inverse, window, 30)
    want = reference_constrained_edge(*args, SHAPE, solver._support_inverse, window, 30)
    assert (free < 0).any() and not np.array_equal(want, free)   # the constraint acts
    # the same cells held; the products summed in another order (loops, not BLAS)
    assert np.array_equal(got == 0.0, want == 0.0)
    assert np.allclose(got, want, rtol=1e-9, atol=1e-12 * np.abs(free).max())
