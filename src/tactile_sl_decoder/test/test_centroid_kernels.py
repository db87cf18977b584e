"""The grey-centroid kernels give the bits of the numpy code they replace (extract/centroid)."""
import numpy as np
import pytest

from tactile_sl_decoder.extract import centroid as ce


def _patches(seed: int, n: int, size: int = 18) -> np.ndarray:
    """Dark glyph-like blobs on tilted, noisy backgrounds, some with a step (misfit)."""
    rng = np.random.default_rng(seed)
    g = np.arange(size) - (size - 1) / 2.0
    x, y = np.meshgrid(g, g)
    back = (rng.uniform(60, 230, (n, 1, 1)) + rng.uniform(-5, 5, (n, 1, 1)) * x
            + rng.uniform(-5, 5, (n, 1, 1)) * y)
    back = np.where((rng.random((n, 1, 1)) < 0.2) & (x > rng.uniform(-6, 6, (n, 1, 1))),
                    back * 0.4, back)
    cx, cy = rng.uniform(-2, 2, (2, n, 1, 1))
    ink = np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / rng.uniform(4, 20, (n, 1, 1)))
    grey = back * (1.0 - 0.8 * ink) + rng.normal(0, rng.uniform(0, 12, (n, 1, 1)), (n, size, size))
    return np.clip(grey, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("n", [1, 5, 256, 700])
def test_plane_thresholds_give_the_numpy_bits(n):
    patches = _patches(n, n)
    flat = np.ascontiguousarray(patches.reshape(n, -1))
    ring, _, basis = ce._border_plane(18)
    for level, tolerance in ((0.5, 0.15), (0.0, 0.1), (1.0, 1.0)):
        thresh, misfit, mean = ce._plane_thresholds(
            flat, ring, ce._border_products(18), basis, np.float32(level),
            np.float32(1.0 - level), np.float32(tolerance))
        assert np.array_equal(thresh, ce._threshold_planes(flat, 18, level, tolerance))
    assert misfit.dtype == bool and mean.dtype == np.float32


@pytest.mark.parametrize("dark", [True, False])
def test_grey_moments_give_the_matrix_products_bits(dark):
    patches = _patches(7, 500)
    flat = np.ascontiguousarray(patches.reshape(500, -1))
    thresh = ce._threshold_planes(flat, 18, 0.5, 0.15)
    for radius in (0.45, 0.3):
        doubled = ce._doubled_kernels(18, radius)
        assert doubled is not None
        mine = ce._grey_moments(flat, thresh, doubled, dark, ce._RECIPROCALS)
        ref = ce._grey_moments_reference(flat, thresh, ce._centroid_kernels(18, radius), dark)
        assert np.array_equal(mine[0], ref[0]) and np.array_equal(mine[1], ref[1])


def test_large_patches_keep_the_matrix_product():
    assert ce._doubled_kernels(18, 0.45) is not None
    assert ce._doubled_kernels(256, 0.45) is None   # moments past float32's exact integers


def test_centroids_fall_back_on_numpy_where_the_kernel_is_not_exact(monkeypatch):
    patches = _patches(3, 64)
    fast = ce.patch_centroid_offset(patches, flatten=True)
    monkeypatch.setattr(ce, "_planes_kernel_is_exact", lambda: False)
    monkeypatch.setattr(ce, "_plane_thresholds", None)   # must not be called
    slow = ce.patch_centroid_offset(patches, flatten=True)
    assert np.array_equal(fast[0], slow[0]) and np.array_equal(fast[1], slow[1])


def test_the_self_check_holds_on_this_machine():
    assert ce._planes_kernel_is_exact()


@pytest.mark.parametrize("gradient", [0.03, -0.03])
def test_centres_follow_the_reflectance_under_an_illumination_gradient(gradient):
    """A bar lit by a light that falls off across it keeps its centre.

    Image = illumination x reflectance: with weights not divided by the threshold, the
    bar's long axis (sigma^2 ~ 8 px^2) times the 3 %/px gradient would lean the centre by
    ~0.25 px towards the brighter side.
    """
    size = 18
    g = np.arange(size) - (size - 1) / 2.0
    x, y = np.meshgrid(g, g)
    # a horizontal bar 10 px long, 3 px wide, soft edges, centred on the patch
    bar = (1 / (1 + np.exp((np.abs(x) - 5.0) / 0.4))) * (1 / (1 + np.exp((np.abs(y) - 1.5) / 0.4)))
    reflectance = 1.0 - 0.85 * bar
    light = 180.0 * (1.0 + gradient * x)
    patch = np.clip(np.rint(light * reflectance), 0, 255).astype(np.uint8)[None]
    # the plane threshold follows the light: the reflectance's centre
    du, dv = ce.patch_centroid_offset(patch, flatten=True)
    assert abs(du[0]) < 0.03 and abs(dv[0]) < 0.03
    unnormalised = np.clip(180.0 - patch[0].astype(float), 0, None) * (x ** 2 + y ** 2 <= 8.1 ** 2)
    lean = (unnormalised * x).sum() / unnormalised.sum()
    assert abs(lean) > 0.15     # what the weights would do without the division
