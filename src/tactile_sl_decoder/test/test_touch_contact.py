"""Contact state, indentation between cells and the depth map."""
import numpy as np

from tactile_sl_decoder.touch.contact import (
    ContactParams,
    contact_state,
    depth_grid,
    depth_map,
    max_indentation,
)


def test_max_indentation_finds_a_paraboloid_peak_between_cells():
    r, c = np.mgrid[0:9, 0:9].astype(float)
    peak = 50e-6 - 2e-6 * ((r - 4.3) ** 2 + (c - 3.6) ** 2)
    assert abs(max_indentation(peak) - 50e-6) < 1e-9
    assert peak.max() <= 50e-6 - 0.49e-6          # no cell holds the peak
    flat = np.full((5, 5), np.nan)
    assert max_indentation(flat) == 0.0
    bulge = -np.ones((5, 5)) * 1e-6
    assert max_indentation(bulge) == 0.0


def test_depth_map_interpolates_and_marks_gaps():
    grid = np.arange(12, dtype=float).reshape(3, 4)
    grid[2, 3] = np.nan
    d = depth_map(grid, 4)
    g = depth_grid((3, 4), 5e-4, 4)
    assert d.shape == (g.height, g.width) == (9, 13) and d.dtype == np.float32
    assert d[0, 0] == 0 and d[0, 4] == 1 and d[4, 4] == 5
    assert abs(d[0, 2] - 0.5) < 1e-6 and abs(d[2, 0] - 2.0) < 1e-6
    assert np.isnan(d[7, 11]) and np.isfinite(d[3, 3])
    assert np.allclose(depth_map(grid, 4, mirrored=True)[:, ::-1], d, equal_nan=True)
    assert g.x0 == -1.5 * 5e-4 and g.resolution == 1.25e-4


def _forces(shape, pressed):
    n = shape[0] * shape[1]
    f = np.zeros((n, 3))
    for (r, c), fz in pressed.items():
        f[r * shape[1] + c, 2] = fz
    rows, cols = np.divmod(np.arange(n), shape[1])
    xy = np.column_stack([(cols - (shape[1] - 1) / 2) * 5e-4, (rows - (shape[0] - 1) / 2) * 5e-4])
    return rows, cols, xy, f


def _wrench(xy, f):
    r = np.column_stack([xy, np.zeros(len(xy))])
    return np.concatenate([f.sum(axis=0), np.cross(r, f).sum(axis=0)])


def test_regions_centroid_area_and_hysteresis():
    shape = (10, 10)
    rows, cols, xy, f = _forces(shape, {(2, 2): -0.01, (2, 3): -0.01, (7, 7): -0.004})
    indent = np.zeros(shape)
    p = ContactParams()
    s = contact_state(xy, rows, cols, f, _wrench(xy, f), shape, 5e-4, indent, False, p)
    assert s.in_contact and abs(s.normal_force - 0.024) < 1e-12
    assert s.cells_in_contact == 3 and abs(s.area - 3 * 25e-8) < 1e-15
    assert len(s.region_force) == 2 and s.region_force[0] > s.region_force[1]
    assert abs(s.region_centroid[0][0] - (2.5 - 4.5) * 5e-4) < 1e-12
    cx = (xy[:, 0] * -f[:, 2]).sum() / 0.024
    cy = (xy[:, 1] * -f[:, 2]).sum() / 0.024
    assert np.allclose(s.centroid, (cx, cy, 0.0), atol=1e-12)
    # hysteresis: 8 mN is below force_on but above force_off
    rows, cols, xy, f = _forces(shape, {(5, 5): -0.008})
    w = _wrench(xy, f)
    assert not contact_state(xy, rows, cols, f, w, shape, 5e-4, indent, False, p).in_contact
    assert contact_state(xy, rows, cols, f, w, shape, 5e-4, indent, True, p).in_contact


def test_noisy_resultant_centroid_defers_to_the_map():
    shape = (10, 10)
    rows, cols, xy, f = _forces(shape, {(4, 4): -0.01, (4, 5): -0.01})
    w = _wrench(xy, f)
    w[3] += 2e-5            # a moment error from far-field noise: 1 mm of centroid at 20 mN
    p = ContactParams()
    exact = contact_state(xy, rows, cols, f, w, shape, 5e-4, np.zeros(shape), False, p)
    assert abs(exact.centroid[1] - (-0.5 * 5e-4 - 1e-3)) < 1e-9     # trusts the resultant
    noisy = contact_state(xy, rows, cols, f, w, shape, 5e-4, np.zeros(shape), False, p,
                          moment_noise=(10.0, 10.0))   # 30 uN m of moment noise
    assert abs(noisy.centroid[1] - (-0.5 * 5e-4)) < 1e-4            # follows the map
