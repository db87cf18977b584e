"""The touch bound: the load model's derivatives, the information and what attains it."""
import math

import numpy as np
import pytest

from tactile_sl_common.elasticity import Elastomer
from tactile_sl_decoder.tooling.bag_runs import DisplacementErrors
from tactile_sl_decoder.tooling.touch_bound import (
    GRID_SPACING,
    PARAMETERS,
    _field,
    centre_within_share,
    draw_variance,
    fisher_information,
    image_variance,
    load_bound,
    load_jacobian,
    scene_bounds,
    smooth_variance,
    within_share,
)
from tactile_sl_decoder.tooling.touch_metrics import cell_keys, key_cells
from tactile_sl_decoder.touch.reference import nominal_positions
from tactile_sl_sim.loads import LoadContact
from tactile_sl_sim.scenes import load_scenes

from ros_harness import BAGS

PAD = Elastomer(3.0e5, 0.49, 0.0)
LIGHT_SCENES = BAGS / "light_scenes.yaml"


def _cells(step: float = 5e-4, half: int = 10) -> np.ndarray:
    g = step * np.arange(-half, half + 1)
    x, y = np.meshgrid(g, g)
    return np.column_stack([x.ravel(), y.ravel()])


def _load(fz: float = -0.1) -> LoadContact:
    return LoadContact(radius=0.003, x=0.0004, y=-0.0003, force=(0.0, 0.0, fz), elastomer=PAD)


def test_force_columns_are_the_field_per_newton_and_centre_columns_its_slope():
    """The displacement is linear in the force, and moving the load by dx is moving the
    cells by -dx: the centre's column is minus the field's spatial slope."""
    cells = _cells()
    load = _load()
    jac = load_jacobian(load, cells)
    assert jac.shape == (len(cells), 3, len(PARAMETERS))
    field = _field(load, cells, GRID_SPACING)
    np.testing.assert_allclose(jac[:, :, 2] * load.force[2], field, atol=1e-3 * np.abs(field).max())
    h = 2e-5
    slope = (_field(load, cells + [h, 0.0], GRID_SPACING)
             - _field(load, cells - [h, 0.0], GRID_SPACING)) / (2 * h)
    # (at the rim the Hertz profile's slope is infinite, and two differences of it differ)
    off_rim = np.abs(np.hypot(*(cells - [load.x, load.y]).T) / load.radius - 1.0) > 0.05
    np.testing.assert_allclose(jac[off_rim, :, 3], -slope[off_rim],
                               atol=0.01 * np.abs(slope).max())
    # a wider disc of the same force presses less deep under its centre
    centre = np.argmin(np.hypot(*(cells - [load.x, load.y]).T))
    assert jac[centre, 2, 5] > 0           # uz < 0 presses; a wider disc: less negative


def test_the_weighted_least_squares_force_attains_the_bound():
    """For the force, which the field is linear in, the inverse-variance weighted least
    squares estimate is efficient: its scatter over noise draws is the bound."""
    rng = np.random.default_rng(3)
    cells = _cells()
    jac = load_jacobian(_load(), cells)[:, :, :3]                 # fx, fy, fz only
    sigma = rng.uniform(2e-6, 12e-6, size=(len(cells), 3))       # uneven, per cell and axis
    info = fisher_information(jac, sigma ** 2)
    bound = np.sqrt(np.diag(np.linalg.inv(info)))
    a = jac.reshape(-1, 3)
    w = 1.0 / (sigma ** 2).reshape(-1)
    truth = np.array([0.0, 0.0, -0.1])
    u = a @ truth
    est = []
    for _ in range(400):
        d = u + (sigma * rng.standard_normal(sigma.shape)).reshape(-1)
        est.append(np.linalg.solve(a.T @ (a * w[:, None]), a.T @ (w * d)))
    scatter = np.std(np.asarray(est), axis=0, ddof=1)
    np.testing.assert_allclose(scatter, bound, rtol=0.1)
    # an unweighted fit of the same data is worse than the bound
    plain = [np.linalg.lstsq(a, u + (sigma * rng.standard_normal(sigma.shape)).reshape(-1),
                             rcond=None)[0][2] for _ in range(400)]
    assert np.std(plain, ddof=1) > 1.2 * bound[2]


def test_information_from_sample_variances_is_scaled_back_and_dead_axes_carry_none():
    jac = np.ones((4, 3, 1))
    var = np.full((4, 3), 2.0)
    assert fisher_information(jac, var)[0, 0] == pytest.approx(6.0)
    assert fisher_information(jac, var, dof=5)[0, 0] == pytest.approx(6.0 * 3 / 5)
    var[0] = np.inf
    var[1, 0] = np.nan
    assert fisher_information(jac, var)[0, 0] == pytest.approx(4.0)


def test_draw_variance_removes_the_shared_bias_and_needs_two_draws():
    rng = np.random.default_rng(0)
    errors = 5e-6 + 2e-6 * rng.standard_normal((200, 10, 3))
    var, dof = draw_variance(errors)
    assert dof == 199
    np.testing.assert_allclose(np.sqrt(var.mean()), 2e-6, rtol=0.05)
    with pytest.raises(ValueError, match="draws >= 2"):
        draw_variance(errors[:1])


def test_smooth_variance_averages_each_cells_present_neighbours():
    rows, cols = np.divmod(np.arange(25), 5)
    keep = np.ones(25, bool)
    keep[12] = False                                   # the centre cell missing
    var = np.arange(25, dtype=np.float64)[:, None] * np.array([1.0, 2.0, 3.0])
    out, count = smooth_variance(var[keep], rows[keep], cols[keep])
    assert count[0] == 4 and count[list(np.flatnonzero(keep)).index(1)] == 6
    assert count[list(np.flatnonzero(keep)).index(6)] == 8       # a neighbour of the hole
    np.testing.assert_allclose(out[0], np.mean([0, 1, 5, 6]) * np.array([1.0, 2.0, 3.0]))
    # noisy sample variances of one true variance come out closer to it
    rng = np.random.default_rng(4)
    rows, cols = np.divmod(np.arange(400), 20)
    sample = rng.chisquare(5, (400, 3)) / 5
    smooth, _ = smooth_variance(sample, rows, cols)
    assert smooth.std() < 0.45 * sample.std()


def test_image_variance_splits_the_point_bound_as_the_measured_noise():
    out = image_variance(np.array([[1.0, 1.0, 8.0], [0.0, 0.0, 0.0]]), np.array([5.0, 3.0]))
    np.testing.assert_allclose(out, [[0.5, 0.5, 4.0], [1.0, 1.0, 1.0]])


def test_shares_within_a_limit():
    assert within_share(1.959964, 1.0) == pytest.approx(0.95, abs=1e-5)
    rng = np.random.default_rng(1)
    xy = 0.07 * rng.standard_normal((200_000, 2))          # rms sqrt(2) * 0.07
    share = float(np.mean(np.hypot(*xy.T) <= 0.1))
    assert centre_within_share(0.1, math.sqrt(2) * 0.07) == pytest.approx(share, abs=0.005)
    assert within_share(1.0, 0.0) == 1.0 and centre_within_share(1.0, 0.0) == 1.0


def test_scene_bounds_from_draws_match_the_bound_of_the_true_noise():
    """Synthetic draws of the clean lighting scene's loads with known noise: the bound from
    their sample variances is the bound of the true variance (within the draws' scatter),
    frame by frame, with the scene's true force."""
    scene = next(s for s in load_scenes(LIGHT_SCENES) if s.name == "light_clean")
    rng = np.random.default_rng(7)
    cells_xy = _cells(half=8)
    keys = np.arange(len(cells_xy), dtype=np.int64)
    sigma = np.array([3e-6, 3e-6, 9e-6])
    draws = []
    for _ in range(40):
        draws.append({scene.stamp_ns(f): DisplacementErrors(
            keys, sigma * rng.standard_normal((len(keys), 3)), cells_xy)
            for f in range(1, scene.frames)})
    bounds = scene_bounds(scene, draws)
    assert [b.frame for b in bounds] == list(range(1, scene.frames))
    for b in bounds:
        load = next(c for c in scene.contacts_at(b.frame) if c.active)
        np.testing.assert_allclose(b.force, load.applied_force)
        assert b.cells == len(keys) and b.draws == 40 and b.images is None
        true = load_bound(load_jacobian(load, cells_xy), np.tile(sigma ** 2, (len(keys), 1)))
        assert b.points.normal_force_sd == pytest.approx(true.normal_force_sd, rel=0.15)
        assert b.points.centre_rms == pytest.approx(true.centre_rms, rel=0.15)


def test_the_image_bound_of_a_frame_is_below_noisier_points():
    """With the scene's renderer the bound also comes from the images' point bounds (frame 0,
    the reference, and the loaded frame): finite, and below that of points far noisier than
    the clean images allow (~0.7 um per point)."""
    import dataclasses

    from tactile_sl_sim.synth import RendererCache

    scene = next(s for s in load_scenes(LIGHT_SCENES) if s.name == "light_clean")
    scene = dataclasses.replace(scene, frames=2)
    renderer = RendererCache().get(scene)
    truth = renderer.render(scene.contacts_at(1), scene.nuisances_at(1), seed=scene.seed,
                            frame_index=1).truth
    art = renderer.artwork
    keys = np.sort(cell_keys(truth.rows, truth.cols))
    rest_xy = nominal_positions(*key_cells(keys), (art.rows, art.cols),
                                art.pitch_m, scene.mirrored)[:, :2]
    rng = np.random.default_rng(2)
    draws = [{scene.stamp_ns(1): DisplacementErrors(
        keys, rng.normal(0.0, [3e-6, 3e-6, 9e-6], (len(keys), 3)), rest_xy)} for _ in range(8)]
    (b,) = scene_bounds(scene, draws, renderer)
    assert b.images is not None
    assert 0 < b.images.normal_force_sd < 0.5 * b.points.normal_force_sd
    assert 0 < b.images.centre_rms < 0.5 * b.points.centre_rms


def test_variance_shares_sum_to_the_bound_and_lie_where_the_information_is(tmp_path):
    """The efficient estimate's variance split over the cells (shares summing to 1); the cells
    that carry most of it lie near the load (its field changes there); the picture shows it."""
    import cv2

    from tactile_sl_decoder.tooling.light_report import write_bound_picture
    from tactile_sl_decoder.tooling.touch_bound import FrameBound, variance_shares

    cells = _cells()
    load = _load()
    jac = load_jacobian(load, cells)
    var = np.tile(np.array([3e-6, 3e-6, 9e-6]) ** 2, (len(cells), 1))
    share = variance_shares(jac, var)
    assert share.min() >= 0 and share.sum() == pytest.approx(1.0)
    distance = np.hypot(*(cells - [load.x, load.y]).T)
    assert share[distance < 1.5 * load.radius].sum() > 0.7
    bound = load_bound(jac, var)
    picture = write_bound_picture(tmp_path / "b.png", "synthetic", FrameBound(
        1, load, np.array(load.force), len(cells), 8, bound, bound, cells, var, var, share))
    image = cv2.imread(str(picture))
    assert image is not None and image.shape[1] > 3 * image.shape[0] > 0
    assert list(tmp_path.iterdir()) == [picture]           # no temporary file left


def test_a_frame_whose_draws_share_too_few_cells_has_no_bound():
    scene = next(s for s in load_scenes(LIGHT_SCENES) if s.name == "light_clean")
    rng = np.random.default_rng(5)
    cells_xy = _cells(half=8)
    draws = []
    for d in range(6):          # each draw decodes other cells: 10 in common
        keys = np.concatenate([np.arange(10), 100 + 100 * d + np.arange(50)]).astype(np.int64)
        draws.append({scene.stamp_ns(1): DisplacementErrors(
            keys, 1e-6 * rng.standard_normal((60, 3)), cells_xy[:60])})
    assert scene_bounds(scene, draws) == []
