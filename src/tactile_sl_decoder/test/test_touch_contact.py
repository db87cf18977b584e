"""Contact state, indentation between cells and the depth map."""
import cv2
import numpy as np
import pytest

from tactile_sl_decoder.touch.contact import (
    _CROSS_CHECK,
    _CURVATURE_SPREAD,
    _DESIGN,
    _FROM_RING,
    _FROM_RING_SPREAD,
    _RING,
    CANDIDATES,
    CURVATURE_SIGMAS,
    FIT_SIGMAS,
    OUTLIER_SIGMAS,
    ContactParams,
    contact_state,
    depth_grid,
    depth_map,
    max_indentation,
    smoothed_map,
)

_DR, _DC = (a.ravel() for a in np.mgrid[-1:2, -1:2])


def reference_max_indentation(indent, noise=3e-6, spread=0.0):
    """The numpy version the compiled kernel is written from."""
    valid = np.isfinite(indent)
    if not valid.any():
        return 0.0
    rows, cols = indent.shape
    pad = 3
    z = np.pad(np.where(valid, indent, 0.0), pad)
    ok = np.pad(valid, pad)
    width = cols + 2 * pad
    step3 = _DR * width + _DC                                 # 3x3 offsets, padded grid
    order = np.flatnonzero(valid.ravel())
    order = order[np.argsort(-indent.ravel()[order], kind="stable")[:CANDIDATES]]
    candidates = (order // cols + pad) * width + order % cols + pad
    # the cells whose status matters: the candidates' 5x5 (their fits and the cross check)
    r5, c5 = np.mgrid[-2:3, -2:3]
    near = np.unique((candidates[:, None] + (r5 * width + c5).ravel()[None, :]).ravel())
    near = near[ok.flat[near]]
    ring = near[:, None] + step3[None, _RING]
    full = ok.flat[ring].all(axis=1)
    from_ring = z.flat[ring] @ _FROM_RING
    limit = OUTLIER_SIGMAS * _FROM_RING_SPREAD * noise
    median = np.median(z.flat[ring], axis=1)
    outlier = full & (np.abs(z.flat[near] - from_ring) > limit) & (
        np.abs(z.flat[near] - median) > limit)
    keep = np.zeros(z.size, bool)
    keep[near[~outlier]] = True
    candidates = candidates[keep[candidates]]
    if len(candidates) == 0:
        kept = indent[valid].max() if not keep.any() else z.flat[np.flatnonzero(keep)].max()
        return max(float(kept), 0.0)
    cells = candidates[:, None] + step3[None, :]              # (m, 9)
    w = keep[cells].astype(np.float64)
    count = w.sum(axis=1)
    usable = count >= 7
    if not usable.any():
        return max(float(z.flat[candidates].max()), 0.0)
    candidates, cells, w, count = candidates[usable], cells[usable], w[usable], count[usable]
    zc = z.flat[cells]
    normal = np.einsum("ik,il,mi->mkl", _DESIGN, _DESIGN, w)
    rhs = np.einsum("ik,mi->mk", _DESIGN, w * zc)
    coef = np.linalg.solve(normal, rhs[..., None])[..., 0]   # (m, 6)
    resid = zc - coef @ _DESIGN.T
    rms = np.sqrt((w * resid ** 2).sum(axis=1) / np.maximum(count - 6, 1))
    smooth = rms <= FIT_SIGMAS * noise
    value = np.where(smooth, coef[:, 0], z.flat[candidates])
    best = int(np.argmax(value))
    c = coef[best]
    peak = float(value[best])
    if not smooth[best]:
        return max(peak, 0.0)
    hessian = np.array([[2 * c[3], c[5]], [c[5], 2 * c[4]]])
    grad = c[1:3]
    curvature, axes = np.linalg.eigh(hessian)
    step = np.zeros(2)
    gain = bent = 0.0
    for lam, axis in zip(curvature, axes.T):
        if lam < -CURVATURE_SIGMAS * _CURVATURE_SPREAD * noise:
            slope = float(grad @ axis)
            step += (-slope / lam) * axis
            gain += -slope * slope / (2.0 * lam)
            bent += lam
    if gain > 0 and np.all(np.abs(step) <= 1.0):
        consistent = True
        checked = 0
        for dr, dc in _CROSS_CHECK.tolist():
            at = candidates[best] + dr * width + dc
            if keep[at]:
                checked += 1
                q = float(c[0] + c[1] * dc + c[2] * dr + c[3] * dc * dc + c[4] * dr * dr
                          + c[5] * dc * dr)
                consistent &= abs(z.flat[at] - q) <= 4.0 * noise + 0.5 * abs(c[0] - q)
        if consistent and checked >= 2:
            peak += gain - 0.5 * spread * spread * bent
    return max(peak, 0.0)


def _random_grid(rng, kind):
    rows, cols = rng.integers(3, 30, 2)
    r, c = np.mgrid[0:rows, 0:cols].astype(float)
    if kind == 0:       # a dome
        g = 50e-6 - rng.uniform(0.5, 20) * 1e-6 * ((r - rng.uniform(0, rows)) ** 2
                                                  + (c - rng.uniform(0, cols)) ** 2)
    elif kind == 1:     # a flat face
        g = np.full((rows, cols), 8e-4)
    elif kind == 2:     # a step (a punch's face and its surroundings)
        g = np.where((r - rows / 2) ** 2 + (c - cols / 2) ** 2 < (rows / 3) ** 2, 8e-4, 3e-4)
    else:
        g = rng.normal(0, 1e-5, (rows, cols))
    g = g + rng.normal(0, rng.choice([1e-7, 1e-6, 3e-6]), g.shape)
    if rng.random() < 0.3:
        g[rng.random(g.shape) < 0.1] = np.nan
    if rng.random() < 0.3:
        g.flat[rng.integers(0, g.size)] += 9e-5
    return g


def test_compiled_max_indentation_equals_the_numpy_version():
    rng = np.random.default_rng(1)
    for i in range(800):
        g = _random_grid(rng, i % 4)
        spread = (0.0, 0.25, 0.6)[i % 3]
        assert max_indentation(g, 3e-6, spread) == pytest.approx(
            reference_max_indentation(g, 3e-6, spread), abs=1e-15)


def test_max_indentation_finds_a_paraboloid_peak_between_cells():
    r, c = np.mgrid[0:9, 0:9].astype(float)
    peak = 50e-6 - 2e-6 * ((r - 4.3) ** 2 + (c - 3.6) ** 2)
    assert abs(max_indentation(peak, noise=1e-8) - 50e-6) < 1e-9
    assert peak.max() <= 50e-6 - 0.49e-6          # no cell holds the peak
    # with 3 um of noise a curvature of 4 um per cell^2 is not told from noise: the fit's
    # value at the cell; a sphere's apex (30 um per cell^2 and more) still moves
    assert 50e-6 - 1e-6 < max_indentation(peak, noise=3e-6) < 50e-6
    sphere = 850e-6 - 15e-6 * ((r - 4.3) ** 2 + (c - 3.6) ** 2)
    assert abs(max_indentation(sphere, noise=3e-6) - 850e-6) < 1e-9
    flat = np.full((5, 5), np.nan)
    assert max_indentation(flat) == 0.0
    bulge = -np.ones((5, 5)) * 1e-6
    assert max_indentation(bulge) == 0.0


def test_max_indentation_undoes_the_glyph_average_of_a_dome():
    """A decoded point averages the surface over its glyph: a dome's cells read shallower."""
    r, c = np.mgrid[0:9, 0:9].astype(float)
    dome = 850e-6 - 15e-6 * ((r - 4.3) ** 2 + (c - 3.6) ** 2)
    # the average over a glyph of spread s (cells, per axis): + s^2 / 2 x the Laplacian
    spread = 0.25
    seen = dome + 0.5 * spread ** 2 * (-60e-6)
    assert max_indentation(seen, 3e-6) == pytest.approx(850e-6 - 1.875e-6, abs=1e-9)
    assert max_indentation(seen, 3e-6, spread) == pytest.approx(850e-6, abs=1e-9)
    # a flat face has no curvature to undo; a cylinder's crest only along its one curvature
    face = np.full((9, 9), 845e-6)
    assert max_indentation(face, 3e-6, spread) == pytest.approx(845e-6, abs=1e-12)
    crest = 700e-6 - 20e-6 * (c - 3.6) ** 2
    assert max_indentation(crest, 3e-6, spread) == pytest.approx(
        700e-6 + 0.5 * spread ** 2 * 40e-6, abs=1e-9)


def test_max_indentation_leaves_out_cells_a_decoder_got_wrong():
    """A flat punch's face with a cell 90 um too deep and one 80 um too shallow at its rim."""
    rng = np.random.default_rng(2)
    r, c = np.mgrid[0:15, 0:15].astype(float)
    face = np.hypot(r - 7.2, c - 6.8) < 4.5
    grid = np.where(face, 845e-6, 845e-6 * 2 / np.pi
                    * np.arcsin(4.5 / np.maximum(np.hypot(r - 7.2, c - 6.8), 4.5)))
    grid += rng.normal(0, 2e-6, grid.shape)
    grid[3, 7] += 90e-6           # at the rim, inside the face
    grid[11, 7] -= 80e-6
    assert abs(max_indentation(grid, 3e-6) - 845e-6) < 5e-6
    assert np.nanmax(grid) > 900e-6          # the deepest cell is the wrong one


def test_max_indentation_of_a_small_flat_top_ringed_by_a_steep_rim():
    """bags/sphere_deep_small against a reference pressed 0.2 mm: a 2 x 3-cell plateau."""
    grid = 1e-6 * np.array([
        [51, 84, 118, 149, 174, 183, 170, 135, 117],
        [82, 127, 178, 224, 264, 278, 258, 221, 169],
        [111, 168, 245, 327, 422, 462, 409, 312, 228],
        [134, 207, 314, 487, 638, 676, 619, 444, 286],
        [152, 230, 372, 601, 700, 695, 694, 554, 334],
        [150, 235, 365, 592, 697, 696, 690, 558, 329],
        [135, 209, 307, 485, 641, 676, 620, 449, 285],
        [114, 170, 240, 329, 424, 465, 400, 309, 224],
        [78, 125, 177, 223, 261, 277, 264, 219, 163]], float)
    assert 690e-6 <= max_indentation(grid, 3e-6) <= 712e-6


def test_max_indentation_does_not_take_a_step_for_a_dome():
    """Three cells across a step fit a parabola; the cells two away tell it is not one."""
    r, c = np.mgrid[0:9, 0:9].astype(float)
    grid = np.where(c <= 4, 845e-6, 620e-6) - 1e-6 * (r - 4) ** 2   # a face ending at column 4
    grid[:, 4] += 8e-6                            # its edge column slightly deeper (noise)
    assert max_indentation(grid, 3e-6) < 845e-6 + 10e-6     # not the parabola's 879 um


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


def test_without_ripples_keeps_the_parts_that_stand_out_of_the_noise():
    from tactile_sl_decoder.touch.contact import RIPPLE_SIGMAS, without_ripples

    shape = (12, 14)
    rows, cols = (a.ravel() for a in np.mgrid[0:shape[0], 0:shape[1]])
    press = np.zeros(len(rows))
    noise = np.full(len(rows), 1e-3)                     # N per cell
    contact = (abs(rows - 3) <= 1) & (abs(cols - 4) <= 1)      # 9 cells, 20 mN each
    press[contact] = 0.02
    speck_a = (rows == 9) & (cols == 11)                  # single cells at 5 sigma
    speck_b = (rows == 1) & (cols == 12)
    press[speck_a | speck_b] = 5e-3
    core = press > 0.2 * press.max()
    assert core[speck_a].all() and core[speck_b].all()     # the peak's fraction keeps them
    kept = without_ripples(core, press, noise, rows, cols, shape)
    assert np.array_equal(kept, contact)
    assert 9 * 0.02 > RIPPLE_SIGMAS * 3 * 1e-3              # the contact: 60 sigma
    # every part a ripple: the one pressing hardest is kept, not none
    faint = without_ripples(core, press * 0.01, noise, rows, cols, shape)
    assert np.array_equal(faint, contact)
    assert not without_ripples(np.zeros(len(rows), bool), press, noise, rows, cols,
                               shape).any()


def test_smoothing_keeps_a_contacts_centroid_and_force_away_from_the_border():
    shape = (32, 32)
    rows, cols, xy, _ = _forces(shape, {})
    r0, c0 = 15.3, 16.6                       # between cells
    bump = np.exp(-((rows - r0) ** 2 + (cols - c0) ** 2) / (2 * 2.5 ** 2))
    assert smoothed_map(bump, rows, cols, shape, 0.0) is bump
    smooth = smoothed_map(bump, rows, cols, shape, 1.0)
    assert abs(smooth.sum() - bump.sum()) < 1e-6 * bump.sum()
    assert np.allclose((smooth[:, None] * xy).sum(0) / smooth.sum(),
                       (bump[:, None] * xy).sum(0) / bump.sum(), atol=1e-9)
    # a cell not decoded presses by nothing: its neighbours are not inflated
    keep = ~((rows == 15) & (cols == 17))
    part = smoothed_map(bump[keep], rows[keep], cols[keep], shape, 1.0)
    assert np.all(part <= smooth[keep] + 1e-12)


def test_a_faint_contacts_map_centroid_is_smoothed_out_of_the_cells_noise():
    """Cell-scale noise on a broad, faint contact: the smoothed core halves the centroid's
    error (the map alone: the resultant's centroid is made uninformative here).

    The noise is white noise less its 3 x 3 mean: an inversion's noise, which its
    regularisation leaves at the scale of a cell (neighbouring cells anti-correlated)."""
    shape = (30, 30)
    rows, cols, xy, _ = _forces(shape, {})
    bump = np.exp(-((rows - 14.3) ** 2 + (cols - 15.6) ** 2) / (2 * 4.0 ** 2))
    bump *= 0.05 / bump.sum()
    truth = (bump[:, None] * xy).sum(0) / bump.sum()
    rng = np.random.default_rng(3)
    errors = {0.0: [], 1.0: []}
    for _ in range(40):
        f = np.zeros((len(rows), 3))
        white = rng.normal(0.0, 0.3 * bump.max(), shape)
        noise = white - cv2.blur(white, (3, 3), borderType=cv2.BORDER_REFLECT)
        f[:, 2] = -(bump + noise.ravel())
        w = _wrench(xy, f)
        for sigma in errors:
            p = ContactParams(centroid_smoothing=sigma)
            s = contact_state(xy, rows, cols, f, w, shape, 5e-4, np.zeros(shape), False, p,
                              moment_noise=(1e6, 1e6))
            errors[sigma].append(np.hypot(*(np.array(s.centroid[:2]) - truth)))
    rms = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in errors.items()}
    assert rms[1.0] < 0.6 * rms[0.0], rms
