"""Geometric outlier rejection (stereo/outliers.py) and the robustness bags of issue 11."""

import numpy as np
import pytest

from tactile_sl_decoder.stereo.outliers import (
    DIRECTIONS,
    OutlierParams,
    _shift,
    surface_outliers,
    surface_residuals,
)

from ros_harness import REPO

PITCH = 5e-4
ROWS, COLS = 30, 28


def _surface(kind: str, noise: float = 3e-6, seed: int = 0):
    """Lattice points of a pressed pad in a camera-like frame (z ~ 15 mm), with noise."""
    rng = np.random.default_rng(seed)
    r, c = np.meshgrid(np.arange(ROWS), np.arange(COLS), indexing="ij")
    r, c = r.ravel(), c.ravel()
    x, y = (c - COLS / 2) * PITCH, (r - ROWS / 2) * PITCH
    rho = np.hypot(x - 1e-3, y + 5e-4)
    if kind == "sphere":                     # 2 mm sphere 0.9 mm deep (Hertz-like profile)
        a = np.sqrt(2e-3 * 9e-4)
        w = np.where(rho < a, 9e-4 - rho**2 / 4e-3,
                     9e-4 / np.pi * ((2 - rho**2 / a**2) * np.arcsin(np.minimum(a / np.maximum(
                         rho, 1e-12), 1)) + np.sqrt(np.maximum(rho**2 / a**2 - 1, 0))))
    elif kind == "crease":                   # edge at 30 deg, 0.5 mm deep, crest radius ~0.7 mm
        d = np.hypot(np.cos(np.radians(30)) * x + np.sin(np.radians(30)) * y, 6e-4)
        w = 5e-4 * np.exp(-(d - 6e-4) / 6e-4)
    else:
        w = np.zeros_like(x)
    xyz = np.column_stack([x, y, 0.015 - w]) + noise * rng.standard_normal((len(x), 3))
    keep = rng.random(len(x)) > 0.03          # a few cells not decoded
    return xyz[keep], r[keep], c[keep]


@pytest.mark.parametrize("kind", ["flat", "sphere", "crease"])
def test_smooth_surfaces_lose_no_point(kind):
    xyz, r, c = _surface(kind)
    assert not surface_outliers(xyz, r, c, (ROWS, COLS)).any()


def test_points_off_the_surface_are_dropped_and_their_neighbours_kept():
    xyz, r, c = _surface("sphere", seed=1)
    rng = np.random.default_rng(2)
    bad = rng.choice(len(xyz), 12, replace=False)
    xyz = xyz.copy()
    xyz[bad, 2] += rng.choice([-1, 1], 12) * rng.uniform(1.5e-4, 6e-4, 12)   # depth errors
    # a cluster: three neighbouring glyphs pulled by the same shadow edge
    cluster = np.flatnonzero((r == 20) & (c >= 5) & (c <= 7))
    xyz[cluster, 2] += 2.5e-4
    # a wrong cell: the point of another cell (one pitch away)
    wrong = np.flatnonzero((r == 8) & (c == 8))
    xyz[wrong, 0] += PITCH
    expected = np.zeros(len(xyz), bool)
    expected[bad] = expected[cluster] = expected[wrong] = True
    out = surface_outliers(xyz, r, c, (ROWS, COLS))
    assert np.array_equal(out, expected)


def test_disabled_or_tiny_clouds_are_left_alone():
    xyz, r, c = _surface("flat")
    xyz[0, 2] += 1e-3
    assert not surface_outliers(xyz, r, c, (ROWS, COLS), OutlierParams(enabled=False)).any()
    assert not surface_outliers(xyz[:5], r[:5], c[:5], (ROWS, COLS)).any()


@pytest.mark.parametrize("name", ["robust_dark_object", "robust_damaged_print",
                                  "robust_textured_object"])
def test_robustness_bags_decode_without_wrong_cells(name):
    from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline
    from tactile_sl_decoder.tooling.bag_runs import evaluate_bag

    bag = REPO / "bags" / f"{name}.mcap"
    if not bag.exists():
        pytest.skip(f"{bag} missing (make bags)")
    pipe = StereoPipeline(PatternSpec.load(), params=PipelineParams(threads=1))
    try:
        _frames, total = evaluate_bag(bag, pipe)
    finally:
        pipe.close()
    assert total.wrong == 0
    assert total.coverage >= 0.98          # damaged glyphs included in the bag's truth
    assert total.rmse_m <= 0.015e-3


def _residuals_reference(grid):
    """The numpy version surface_residuals replaced (kept as the reference)."""
    centre = _shift(grid, 0, 0)
    best = np.full(centre.shape[:2], np.inf)
    one_sided = np.full(centre.shape[:2], np.inf)
    for dr, dc in DIRECTIONS:
        a1, b1 = _shift(grid, -dr, -dc), _shift(grid, dr, dc)
        a2, b2 = _shift(grid, -2 * dr, -2 * dc), _shift(grid, 2 * dr, 2 * dc)
        pred4 = (4.0 * (a1 + b1) - a2 - b2) / 6.0
        pred2 = 0.5 * (a1 + b1)
        pred = np.where(np.isfinite(pred4), pred4, pred2)
        best = np.fmin(best, np.linalg.norm(centre - pred, axis=-1))
        for p1, p2 in ((a1, a2), (b1, b2)):
            one_sided = np.fmin(one_sided, np.linalg.norm(centre - (2.0 * p1 - p2), axis=-1))
    res = np.where(np.isfinite(best), best, one_sided)
    return np.where(np.isfinite(res) & np.isfinite(centre[..., 0]), res, np.nan)


@pytest.mark.parametrize("seed,holes", [(0, 0.0), (1, 0.2), (2, 0.7)])
def test_residuals_equal_the_numpy_reference_bit_for_bit(seed, holes):
    rng = np.random.default_rng(seed)
    grid = np.full((30 + 4, 28 + 4, 3), np.nan)
    r, c = np.mgrid[0:30, 0:28]
    pts = np.stack([c * 5e-4, r * 5e-4, 0.015 + 1e-4 * np.sin(c / 4.0) * np.cos(r / 5.0)], -1)
    pts += rng.normal(0, 2e-6, pts.shape)
    pts[rng.random((30, 28)) < holes] = np.nan
    pts[3, 4] += (0, 0, 3e-4)                      # an outlier
    grid[2:-2, 2:-2] = pts
    assert np.array_equal(surface_residuals(grid), _residuals_reference(grid), equal_nan=True)
