"""Glyph centres fitted with the printed artwork (stereo/artwork_fit.py) and the pipeline's
use of them (artwork_fit.enabled)."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from tactile_sl_common.images import to_gray
from tactile_sl_decoder.extract.extraction import extract_symbols
from tactile_sl_decoder.frames import bag_frames
from tactile_sl_decoder.pattern import default_pattern_path, load_pattern
from tactile_sl_decoder.pattern.constraints import Constraints
from tactile_sl_decoder.pattern.fileio import Pattern
from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline
from tactile_sl_decoder.stereo.artwork_fit import (
    ArtworkFitParams,
    ArtworkModel,
    fit_centres,
    lattice_maps,
)
from tactile_sl_decoder.tooling.e2e_metrics import frame_metrics

from ros_harness import REPO

BAG = REPO / "bags" / "sphere_deep_small.mcap"
ON = ArtworkFitParams(enabled=True, blur_sigma_px=0.5)


@pytest.fixture(scope="module")
def model():
    pattern = load_pattern(default_pattern_path())
    return ArtworkModel(pattern)


@pytest.fixture(scope="module")
def still():
    """A still pad rendered without noise (18 px spacing, 0.5 px blur): the left image, the
    extraction's centroids of the visible glyphs, their cells and their true centres."""
    from tactile_sl_sim.artwork import load_artwork
    from tactile_sl_sim.optics import RigParams, SimulatedCameraPair
    from tactile_sl_sim.render import Nuisances, Renderer

    renderer = Renderer(load_artwork(), SimulatedCameraPair(RigParams.for_glyph_spacing(18.0)),
                        supersample=4)
    nz = Nuisances.from_dict({"blur_sigma": 0.5, "noise_sigma": 0.0, "shot_noise": 0.0,
                              "vignetting": 0.0})
    frame = renderer.render([], nz, seed=1, frame_index=0)
    truth = frame.truth
    det = extract_symbols(frame.left)
    found = np.column_stack([det.u, det.v]).astype(np.float64)
    visible = np.flatnonzero(truth.visible)
    dist, near = cKDTree(truth.px_left[visible]).query(found)
    ok = dist < 4.0
    cell = visible[near[ok]]
    return frame.left, found[ok], truth.rows[cell], truth.cols[cell], truth.px_left[cell]


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))


def test_the_lattice_map_is_recovered_from_the_neighbours():
    rows, cols = (a.reshape(-1) for a in np.mgrid[0:7, 0:8])
    jac = np.array([[17.5, 1.2], [-0.8, 18.3]])
    quad = np.array([[0.05, -0.02, 0.03], [0.01, 0.04, -0.06]])
    q = np.column_stack([cols, rows]).astype(float)
    terms = np.column_stack([q[:, 0] ** 2, q[:, 1] ** 2, q[:, 0] * q[:, 1]])
    uv = 100.0 + q @ jac.T + terms @ quad.T
    j, qd, rms, count = lattice_maps(uv, rows, cols)
    inner = (rows == 3) & (cols == 4)
    assert count[inner] == 25
    assert rms[inner] < 1e-6
    # J at the glyph: the linear part of the map there (the quadratic's slope at its cell)
    slope = jac + np.array([[2 * quad[0, 0] * 4 + quad[0, 2] * 3,
                             2 * quad[0, 1] * 3 + quad[0, 2] * 4],
                            [2 * quad[1, 0] * 4 + quad[1, 2] * 3,
                             2 * quad[1, 1] * 3 + quad[1, 2] * 4]])
    np.testing.assert_allclose(j[inner][0], slope, atol=1e-6)
    np.testing.assert_allclose(qd[inner][0], quad, atol=1e-6)
    corner = (rows == 0) & (cols == 0)
    assert count[corner] == 9


@pytest.mark.parametrize("mirrored", [False, True])
def test_fitted_centres_are_closer_to_the_truth_than_the_centroids(still, model, mirrored):
    """Noise-free: the centroid's bias (threshold, window, neighbours) is 0.006-0.012 px per
    axis; the fit, which models the glyph and its neighbours, leaves about half of it.  A
    mirrored image (the lattice's map reflects) fits alike."""
    gray, uv, rows, cols, true = still
    if mirrored:
        width = gray.shape[1]
        gray = np.ascontiguousarray(gray[:, ::-1])
        uv = np.column_stack([width - 1 - uv[:, 0], uv[:, 1]])
        true = np.column_stack([width - 1 - true[:, 0], true[:, 1]])
    fitted, ok = fit_centres(gray, uv, rows, cols, model, ON)
    assert ok.mean() > 0.95
    before, after = _rms(uv[ok] - true[ok]), _rms(fitted[ok] - true[ok])
    assert before > 0.01
    assert after < 0.6 * before
    np.testing.assert_array_equal(fitted[~ok], uv[~ok])


def test_glyphs_without_a_lattice_around_them_keep_their_centroids(still, model):
    gray, uv, rows, cols, _true = still
    # every third cell of every third row: no glyph has a decoded neighbour within two cells
    sparse = (rows % 3 == 0) & (cols % 3 == 0)
    fitted, ok = fit_centres(gray, uv[sparse], rows[sparse], cols[sparse], model, ON)
    assert not ok.any()
    np.testing.assert_array_equal(fitted, uv[sparse])
    # a glyph whose neighbours are off any smooth lattice (a kink) keeps its centroid
    bent = uv.copy()
    centre = int(np.flatnonzero((rows == 12) & (cols == 12))[0])
    near = (np.abs(rows - 12) <= 2) & (np.abs(cols - 12) <= 2) & (cols > 12)
    bent[near, 0] += 3.0
    fitted, ok = fit_centres(gray, bent, rows, cols, model, ON)
    assert not ok[centre]
    assert fitted[centre, 0] == bent[centre, 0]
    assert ok.mean() > 0.9


def test_a_window_without_ink_is_not_fitted(still, model):
    """No ink (a flat or a noise image where the lattice says glyphs are): no fit, the
    centroids are kept."""
    gray, uv, rows, cols, _true = still
    for image in (np.full_like(gray, 200),
                  np.random.default_rng(0).integers(0, 256, gray.shape, dtype=np.uint8)):
        fitted, ok = fit_centres(image, uv, rows, cols, model, ON)
        assert not ok.any()
        np.testing.assert_array_equal(fitted, uv)


def test_params_are_checked_and_a_pattern_needs_its_glyphs():
    with pytest.raises(ValueError, match="artwork_fit.radius"):
        ArtworkFitParams(radius=5.0).validate()
    with pytest.raises(ValueError, match="artwork_fit.passes"):
        StereoPipeline(PatternSpec.load(), params=PipelineParams(
            threads=1, artwork_fit=ArtworkFitParams(passes=0)))
    with pytest.raises(ValueError, match="glyph names"):
        ArtworkModel(Pattern(np.array([[0, 1], [2, 3]]), Constraints(4, (3, 3), 1),
                             primitives=["line", "circle", "triangle"]))


def test_the_pipeline_triangulates_the_fitted_centres(still):
    """A pressed frame of a bundled bag: with the fit the points are closer to the truth, the
    glyph arrays (SymbolArray outputs) stay as extracted, and the two images may be fitted in
    two threads."""
    frame = list(bag_frames(BAG))[4]
    images = (to_gray(frame.left_image), to_gray(frame.right_image), frame.left_info,
              frame.right_info)
    truth = frame.ground_truth
    results = {}
    for enabled, threads in ((False, 1), (True, 1), (True, 2)):
        params = PipelineParams(threads=threads)
        params.artwork_fit.enabled = enabled
        pipe = StereoPipeline(PatternSpec.load(), params=params)
        results[enabled, threads] = pipe.process(*images)
        pipe.close()
    off, on = results[False, 1], results[True, 1]
    # the two images fitted in two threads: the same points
    assert results[True, 2].points.tobytes() == on.points.tobytes()
    np.testing.assert_array_equal(off.left.u, on.left.u)
    np.testing.assert_array_equal(off.right.v, on.right.v)
    assert len(on.points) == len(off.points)
    tol = 0.5 * PatternSpec.load().pitch_m
    err_off = frame_metrics(off.points, truth, tol).errors_m
    err_on = frame_metrics(on.points, truth, tol).errors_m
    rmse_off, rmse_on = (float(np.sqrt(np.mean(np.asarray(e) ** 2))) for e in (err_off, err_on))
    assert rmse_on < 0.85 * rmse_off


def test_a_cell_without_its_glyph_is_not_fitted_as_ink(still, model):
    """A glyph's ink gone (dropout) and so undecoded: the artwork's ink there is not what the
    image shows, and its neighbour's fit leaves those pixels out."""
    gray, uv, rows, cols, true = still
    centre = int(np.flatnonzero((rows == 12) & (cols == 12))[0])
    erased = (np.abs(rows - 12) <= 1) & (cols == 13)
    image = gray.copy()
    h, w = image.shape
    yy, xx = np.mgrid[0:h, 0:w]
    for k in np.flatnonzero(erased):
        near = (xx - true[k, 0]) ** 2 + (yy - true[k, 1]) ** 2 <= (0.45 * 18.0) ** 2
        image[near] = np.percentile(gray[near], 95)          # the pad's grey there
    keep = ~erased
    index = int(np.flatnonzero(np.flatnonzero(keep) == centre)[0])
    fitted, ok = fit_centres(image, uv[keep], rows[keep], cols[keep], model, ON)
    assert ok[index]
    error = float(np.hypot(*(fitted[index] - true[centre])))
    typical = float(np.median(np.hypot(*(fitted[ok] - true[keep][ok]).T)))
    assert error < max(3.0 * typical, 0.01)


def test_a_neighbour_off_the_lattice_does_not_bend_its_neighbours_fits(still, model):
    """A worn glyph's centroid, a pixel off its place, is left out of the lattice map its
    neighbours' fits use (``map_outlier_px``): they are fitted as if it were not there.
    Without it their lattice departs from its quadratic and they keep their centroids."""
    gray, uv, rows, cols, true = still
    worn = int(np.flatnonzero((rows == 12) & (cols == 13))[0])
    moved = uv.copy()
    moved[worn] += (1.0, 0.8)
    near = np.flatnonzero((np.abs(rows - 12) <= 1) & (np.abs(cols - 13) <= 1))
    near = near[near != worn]
    clean, _ = fit_centres(gray, uv, rows, cols, model, ON)
    fitted, ok = fit_centres(gray, moved, rows, cols, model, ON)
    assert ok[near].all()
    assert _rms(fitted[near] - true[near]) < 1.2 * _rms(clean[near] - true[near]) + 0.001
    plain = ArtworkFitParams(enabled=True, blur_sigma_px=0.5, map_outlier_px=0.0)
    _, ok = fit_centres(gray, moved, rows, cols, model, plain)
    assert not ok[near].any()
