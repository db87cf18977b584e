"""The Cramer-Rao bound of glyph centres and 3-D points (tooling/centre_bound.py)."""
import numpy as np
import pytest

from tactile_sl_decoder.stereo.stereo import StereoRig
from tactile_sl_decoder.tooling.centre_bound import (
    best_share_rmse,
    centre_covariance_bound,
    point_error_bound,
)
from tactile_sl_sim.optics import RigParams, SimulatedCameraPair

SIZE = 41
CENTRE = (20.3, 19.6)
DEPTH, WIDTH, BACKGROUND, READ = 60.0, 2.5, 150.0, 4.0


def _blob(centre=CENTRE) -> np.ndarray:
    """A dark Gaussian glyph on a flat background (grey levels)."""
    v, u = np.mgrid[0:SIZE, 0:SIZE].astype(float)
    r2 = (u - centre[0]) ** 2 + (v - centre[1]) ** 2
    return BACKGROUND - DEPTH * np.exp(-0.5 * r2 / WIDTH ** 2)


def test_bound_of_a_gaussian_blob_is_the_analytic_one():
    # Read noise only: J_uu = (A / sigma)^2 * integral (x / s^2)^2 exp(-r^2 / s^2) = pi A^2 /
    # (2 sigma^2), independent of the width; u and v uncorrelated.
    cov = centre_covariance_bound(_blob(), np.array([CENTRE]), 15, READ, 0.0)[0]
    analytic = 2.0 * READ ** 2 / (np.pi * DEPTH ** 2)
    assert abs(cov[0, 0] / analytic - 1) < 0.03
    assert abs(cov[1, 1] / analytic - 1) < 0.03
    assert abs(cov[0, 1]) < 0.01 * analytic


def test_an_efficient_estimator_reaches_the_bound_and_none_beats_it():
    """Least squares of the known blob's position (maximum likelihood here) over noise draws:
    its variance is the bound (within the spread of 400 draws); a centroid's is above it."""
    rng = np.random.default_rng(7)
    truth = np.array(CENTRE)
    bound = centre_covariance_bound(_blob(), truth[None], 15, READ, 0.0)[0]
    fits, centroids = [], []
    v, u = np.mgrid[0:SIZE, 0:SIZE].astype(float)
    for _ in range(400):
        img = _blob() + READ * rng.standard_normal((SIZE, SIZE))
        est = truth + rng.normal(0, 0.2, 2)          # start off the truth
        for _ in range(6):                            # Gauss-Newton on (u, v)
            model = _blob(est)
            gv, gu = np.gradient(model)
            jac = -np.column_stack([gu.ravel(), gv.ravel()])
            step = np.linalg.lstsq(jac, (img - model).ravel(), rcond=None)[0]
            est = est + step
        fits.append(est)
        w = np.maximum(BACKGROUND - img, 0.0)
        centroids.append([np.sum(w * u) / w.sum(), np.sum(w * v) / w.sum()])
    fit_var = np.var(np.array(fits) - truth, axis=0)
    centroid_mse = np.mean((np.array(centroids) - truth) ** 2, axis=0)
    assert np.all(fit_var > 0.8 * np.diag(bound))
    assert np.all(fit_var < 1.25 * np.diag(bound))
    assert np.all(centroid_mse > 1.5 * np.diag(bound))


def test_shot_noise_and_a_flat_window_and_the_image_edge():
    img = _blob()
    with_shot = centre_covariance_bound(img, np.array([CENTRE]), 15, READ, 0.3)[0]
    without = centre_covariance_bound(img, np.array([CENTRE]), 15, READ, 0.0)[0]
    assert with_shot[0, 0] > 2 * without[0, 0]        # 4^2 + 0.3 * ~120 grey levels of variance
    flat = centre_covariance_bound(np.full((SIZE, SIZE), 100.0), np.array([CENTRE]), 15,
                                   READ, 0.0)[0]
    assert np.isinf(flat).all()
    outside = centre_covariance_bound(img, np.array([[500.0, 500.0]]), 5, READ, 0.0)[0]
    assert np.isinf(outside).all()


def test_point_bound_is_the_triangulated_scatter_of_such_centres():
    """Monte Carlo through the decoder's own triangulation agrees with the linearised bound."""
    pair = SimulatedCameraPair(RigParams())
    rig = StereoRig(pair.left_info, pair.right_info)
    rng = np.random.default_rng(1)
    pad = np.column_stack([rng.uniform(-0.003, 0.003, 20), rng.uniform(-0.002, 0.002, 20),
                           rng.uniform(-0.0005, 0.0, 20)])     # world (pad) points
    px_l, px_r = pair.left.project(pad), pair.right.project(pad)
    cov_l = np.tile(np.diag([0.04, 0.09]), (20, 1, 1))
    cov_r = np.tile(np.array([[0.05, 0.01], [0.01, 0.03]]), (20, 1, 1))
    bound = point_error_bound(rig, px_l, px_r, cov_l, cov_r)
    base = rig.triangulate(px_l, px_r)[0]
    draws = 2000
    sq = np.zeros(20)
    for _ in range(draws):
        nl = np.einsum("nij,nj->ni", np.linalg.cholesky(cov_l), rng.standard_normal((20, 2)))
        nr = np.einsum("nij,nj->ni", np.linalg.cholesky(cov_r), rng.standard_normal((20, 2)))
        sq += np.sum((rig.triangulate(px_l + nl, px_r + nr)[0] - base) ** 2, axis=1)
    assert np.allclose(sq / draws, bound, rtol=0.1)
    cov_l[3] = np.inf
    assert np.isinf(point_error_bound(rig, px_l, px_r, cov_l, cov_r)[3])


def test_best_share_rmse_keeps_the_smallest_bounds():
    b = np.array([4.0, 1.0, 9.0, 1.0])
    assert best_share_rmse(b, 1.0) == np.sqrt(15.0 / 4)
    assert best_share_rmse(b, 0.5) == 1.0
    assert np.isnan(best_share_rmse(b, 0.1))


@pytest.mark.slow          # 20 renders, ~6 s
def test_frame_bounds_of_a_simulated_press_scale_with_the_read_noise():
    """Read noise only: the information is 1 / sigma^2, so doubling sigma quadruples every
    glyph's bound exactly; every visible glyph gets a finite, plausible one."""
    from tactile_sl_decoder.tooling.centre_bound import frame_point_bounds
    from tactile_sl_sim.artwork import load_artwork
    from tactile_sl_sim.contact import Contact
    from tactile_sl_sim.render import Nuisances, Renderer

    renderer = Renderer(load_artwork())
    rig = StereoRig(renderer.rig.left_info, renderer.rig.right_info)
    press = [Contact("sphere", radius=0.004, depth=0.0005, x=0.0003, y=-0.0002)]
    bounds = [frame_point_bounds(renderer, rig, press,
                                 Nuisances(noise_sigma=sigma, shot_noise=0.0, blur_sigma=0.8),
                                 seed=3, frame_index=0, spacing_px=18.0)
              for sigma in (1.0, 2.0)]
    truth = renderer.render(press, Nuisances(), seed=3).truth
    assert len(bounds[0]) == truth.visible.sum()
    assert np.isfinite(bounds[0]).mean() > 0.99
    ok = np.isfinite(bounds[0])
    assert np.allclose(bounds[1][ok] / bounds[0][ok], 4.0, rtol=1e-6)
    rms = np.sqrt(np.median(bounds[0][ok]))
    assert 1e-8 < rms < 1e-5        # well under a micrometre .. 10 um at 1 grey level of noise
