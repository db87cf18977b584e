"""Simulator nuisances of real sensors (issue 11): off by default, in range, doing what they say."""

import numpy as np
import pytest

from tactile_sl_common.bag_io import BagReader
from tactile_sl_common.images import to_gray
from tactile_sl_sim.artwork import load_artwork
from tactile_sl_sim.contact import Contact
from tactile_sl_sim.render import Nuisances, Renderer, _line_kernel, _pillbox
from tactile_sl_sim.scenes import load_scenes
from tactile_sl_sim.synth import RendererCache, render_scene_frame

from ros_harness import REPO

PRESS = [Contact("sphere", radius=0.004, depth=0.0006, x=0.0003, y=-0.0002)]


@pytest.fixture(scope="module")
def renderer():
    return Renderer(load_artwork())


@pytest.mark.slow
def test_defaults_are_off_and_bundled_bag_frame_is_unchanged():
    nz = Nuisances()
    assert not nz.damages_print and not nz.see_through and not nz.jpeg_quality
    assert nz.dust == 0 and nz.defocus_px == 0 and nz.motion_blur_px == 0
    assert nz.exposure_right == 1.0 and nz.exposure_jitter_camera == 0
    # the first frame of a bundled bag renders to the very same bytes as before the keys
    scene = next(s for s in load_scenes(REPO / "bags" / "scenes.yaml") if s.name == "no_contact")
    frame = render_scene_frame(scene, RendererCache().get(scene), 0)
    first: dict[str, object] = {}      # the first image of each camera: frame 0's stamp
    for raw, msg in BagReader(REPO / "bags" / "no_contact.mcap").messages(
            ["/tactile/left/image_raw", "/tactile/right/image_raw"]):
        first.setdefault(raw.topic.split("/")[2], msg)
    assert first["left"].header.stamp == first["right"].header.stamp
    assert np.array_equal(frame.left, to_gray(first["left"]))
    assert np.array_equal(frame.right, to_gray(first["right"]))


@pytest.mark.parametrize("doc", [{"jpeg_quality": 101}, {"see_through": "glass"},
                                 {"dropout": 1.0}, {"defocus_px": -1.0}, {"dust_strength": 2},
                                 {"exposure_right": 0.0}, {"object_contrast": 0.5}])
def test_out_of_range_values_are_refused(doc):
    with pytest.raises(ValueError):
        Nuisances.from_dict(doc)


def test_blur_kernels_are_normalised_and_centred():
    for k in (_pillbox(2.5), _line_kernel(7.0, 30.0), _line_kernel(2.0, 0.0)):
        assert k.shape[0] % 2 == 1 and abs(float(k.sum()) - 1.0) < 1e-5
        n = k.shape[0] // 2
        ys, xs = np.mgrid[0:k.shape[0], 0:k.shape[1]]
        assert abs(float((k * xs).sum()) - n) < 1e-5 and abs(float((k * ys).sum()) - n) < 1e-5


@pytest.mark.slow
def test_camera_nuisances_change_the_images(renderer):
    base = renderer.render(PRESS, Nuisances(), seed=1)
    jpeg = renderer.render(PRESS, Nuisances(jpeg_quality=50), seed=1)
    assert not np.array_equal(base.left, jpeg.left)
    assert np.abs(base.left.astype(int) - jpeg.left.astype(int)).mean() < 6   # noise, blocks
    dim = renderer.render(PRESS, Nuisances(exposure_right=0.7), seed=1)
    assert np.array_equal(dim.left, base.left)
    ratio = dim.right.mean() / base.right.mean()
    assert 0.65 < ratio < 0.75
    blurred = renderer.render(PRESS, Nuisances(motion_blur_px=6.0), seed=1)
    assert np.std(np.diff(blurred.left.astype(float), axis=1)) < np.std(
        np.diff(base.left.astype(float), axis=1))


@pytest.mark.slow
def test_dark_object_is_seen_in_the_contact_area_only(renderer):
    base = renderer.render(PRESS, Nuisances(noise_sigma=0, shot_noise=0), seed=1)
    dark = renderer.render(PRESS, Nuisances(noise_sigma=0, shot_noise=0, see_through="dark"),
                           seed=1)
    diff = base.left.astype(int) - dark.left.astype(int)
    centre = np.round(base.truth.px_left[np.argmin(np.abs(base.truth.world[:, 0] - 0.0003)
                                                   + np.abs(base.truth.world[:, 1] + 0.0002))])
    u, v = int(centre[0]), int(centre[1])
    assert diff[v - 10:v + 10, u - 10:u + 10].mean() > 40        # object under the glyphs
    assert np.abs(diff[:40, :40]).max() == 0                     # untouched pad unchanged
    flat = renderer.render([], Nuisances(see_through="text", object_contrast=0.1), seed=1)
    assert np.array_equal(flat.left, renderer.render([], Nuisances(), seed=1).left)


@pytest.mark.slow
def test_print_damage_is_fixed_per_seed_and_in_the_truth(renderer):
    nz = Nuisances(dropout=0.05, wear=0.05, scratches=3, bubbles=2)
    a = renderer.render([], nz, seed=4)
    b = renderer.render([], nz, seed=4, frame_index=1)
    clean = renderer.render([], Nuisances(), seed=4)
    assert a.truth.damaged is not None and a.truth.damaged.sum() > 20
    assert np.array_equal(a.truth.damaged, b.truth.damaged)
    gone = clean.truth.visible & ~a.truth.visible
    assert 0.02 < gone.sum() / clean.truth.visible.sum() < 0.09
    assert not np.array_equal(renderer.render([], nz, seed=5).truth.visible, a.truth.visible)


@pytest.mark.slow
def test_dust_darkens_fixed_specks_and_flags_their_glyphs(renderer):
    nz = Nuisances(dust=20, dust_radius_px=3.0, dust_strength=0.8, noise_sigma=0,
                   shot_noise=0)
    a = renderer.render([], nz, seed=2)
    clean = renderer.render([], Nuisances(noise_sigma=0, shot_noise=0), seed=2)
    specks = renderer.dust_specks(0, nz, 2)
    u, v = int(specks[0, 0]), int(specks[0, 1])
    assert a.left[v, u] < clean.left[v, u]
    assert a.truth.damaged.sum() > 0
    assert np.array_equal(a.truth.visible, clean.truth.visible)


def test_linear_signal_and_printing_only_some_cells(renderer):
    """The analysis renders (tools/bench_sweep.py --bound): the linear signal is the image
    before noise, gamma and quantisation, and the image is linear in which glyphs are printed."""
    nz = Nuisances(noise_sigma=0.0, shot_noise=0.0, see_through="dark", object_albedo=0.3)
    image = renderer.render(PRESS, nz, seed=4).left
    linear = renderer.render(PRESS, nz, seed=4, linear=True)
    assert linear.left.dtype == np.float32
    # the same values but for the last bit of the 8-bit conversion's rounding
    assert np.abs(np.clip(linear.left, 0, 255) - image).max() <= 0.5 + 1e-3
    art = renderer.artwork
    cells = art.rows * art.cols
    none = renderer.render(PRESS, nz, seed=4, ink_cells=np.zeros(cells, bool), linear=True)
    one_in_nine = (np.arange(cells) // art.cols % 3 == 0) & (np.arange(cells) % art.cols % 3 == 0)
    part = renderer.render(PRESS, nz, seed=4, ink_cells=one_in_nine, linear=True)
    rest = renderer.render(PRESS, nz, seed=4, ink_cells=~one_in_nine, linear=True)
    # ink only darkens; the glyphs' shares add up to the whole print
    assert (none.left >= linear.left - 1e-3).all() and none.left.max() > linear.left.max() - 1
    own = part.left - none.left
    assert own.min() < -20 and np.allclose(own + rest.left, linear.left, atol=0.05)
    # the printed cells' truth is the same scene's
    assert np.array_equal(part.truth.px_left, linear.truth.px_left)
    with pytest.raises(ValueError, match="ink_cells has 3 entries"):
        renderer.render(PRESS, nz, ink_cells=np.ones(3, bool))
