"""Simulator acceptance: ground truth consistent with CameraInfo and with the rendered ink."""
import cv2
import numpy as np
import pytest

from tactile_sl_common.camera_info import calibration_from_msg, stereo_baseline
from tactile_sl_common.clouds import cloud_to_arrays
from tactile_sl_sim.artwork import ArtworkError, load_artwork, random_values, write_artwork
from tactile_sl_sim.contact import Contact
from tactile_sl_sim.render import Nuisances, Renderer
from tactile_sl_sim.scenes import Scene
from tactile_sl_sim.synth import frame_messages

# Renders full stereo frames (seconds each on two cores): `make test`, not `make unit`.
pytestmark = pytest.mark.slow


class _Msg:
    """Attribute access over a fields dict (what a bag decoder gives)."""

    def __init__(self, d):
        for k, v in d.items():
            setattr(self, k, _Msg(v) if isinstance(v, dict) else v)


@pytest.fixture(scope="module")
def artwork_path(tmp_path_factory):
    return write_artwork(tmp_path_factory.mktemp("art") / "pattern.png", random_values(30, 28))


@pytest.fixture(scope="module")
def renderer(artwork_path):
    return Renderer(load_artwork(artwork_path))


SCENES = {
    "flat": [],
    "deep_sphere": [Contact("sphere", radius=0.002, depth=0.0009, x=-0.0008, y=0.0005,
                            shear=(0.00015, -0.00005))],
    "punch_and_cylinder": [
        Contact("flat", radius=0.0012, depth=0.0004, x=-0.0028, y=-0.0018, fillet=0.00015),
        Contact("cylinder", radius=0.002, length=0.003, angle=np.radians(60), depth=0.0006,
                x=0.0025, y=0.0016)],
    "edge": [Contact("edge", radius=0.0008, angle=np.radians(30), depth=0.0005)],
}


def _retriangulate(left, right, px_l, px_r):
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
    rl = cv2.undistortPoints(px_l.reshape(-1, 1, 2), left.K, left.D, R=left.R, P=left.P,
                             criteria=crit).reshape(-1, 2)
    rr = cv2.undistortPoints(px_r.reshape(-1, 1, 2), right.K, right.D, R=right.R, P=right.P,
                             criteria=crit).reshape(-1, 2)
    X = cv2.triangulatePoints(left.P, right.P, rl.T, rr.T)
    rect = (X[:3] / X[3]).T
    return rect @ left.R  # rectified left frame -> physical left frame (R^T x)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_retriangulated_ground_truth_within_a_micrometre(renderer, name):
    frame = renderer.render(SCENES[name], seed=3)
    scene = Scene(name="t")
    msgs = {t: _Msg(f) for t, _s, f in frame_messages(scene, renderer, frame, 1_700_000_000)}
    left = calibration_from_msg(msgs["left/camera_info"])
    right = calibration_from_msg(msgs["right/camera_info"])
    assert 0.0035 < stereo_baseline(left, right) < 0.0045
    cloud = cloud_to_arrays(msgs["ground_truth/points"])
    truth = frame.truth
    v = truth.visible
    assert v.sum() > 500 and len(cloud) == v.sum()
    xyz = _retriangulate(left, right, truth.px_left[v], truth.px_right[v])
    err = np.linalg.norm(xyz - truth.xyz[v], axis=1)
    assert err.max() < 1e-6, f"max re-triangulation error {err.max() * 1e6:.4f} um"
    cloud_xyz = np.stack([cloud["x"], cloud["y"], cloud["z"]], axis=1).astype(np.float64)
    assert np.abs(cloud_xyz - truth.xyz[v]).max() < 1e-6
    assert (cloud["row"] == truth.rows[v]).all() and (cloud["col"] == truth.cols[v]).all()
    # a contact pushes the pad towards the cameras: some points closer than the rest plane
    if name != "flat":
        assert truth.world[:, 2].min() < -0.0003


def _ink_offsets(image, px, radius):
    """Distance from each projected centre to the ink centroid in a window around it.

    Ink = how much darker than the local background (morphological closing, which follows
    shading but removes glyph-sized dark marks) a pixel is.
    """
    img = image.astype(np.float32)
    k = int(2 * radius) | 1
    bg = cv2.morphologyEx(img, cv2.MORPH_CLOSE,
                          cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k + 4, k + 4)))
    ink_img = np.clip(bg - img, 0, None)
    h, w = img.shape
    out = []
    r = int(np.ceil(radius))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    disk = (xx**2 + yy**2) <= radius**2
    for x, y in px:
        cx, cy = int(round(x)), int(round(y))
        if not (r <= cx < w - r and r <= cy < h - r):
            out.append(np.nan)
            continue
        ink = ink_img[cy - r:cy + r + 1, cx - r:cx + r + 1] * disk
        ink[ink < 0.3 * ink.max()] = 0  # clear ink only (noise and faint halos out)
        if ink.sum() <= 0:
            out.append(np.inf)
            continue
        mx = (ink * (xx + cx)).sum() / ink.sum()
        my = (ink * (yy + cy)).sum() / ink.sum()
        out.append(np.hypot(mx - x, my - y))
    return np.array(out)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_ground_truth_centres_land_on_their_glyph_ink(renderer, name):
    frame = renderer.render(SCENES[name], seed=5)
    truth = frame.truth
    v = truth.visible
    spacing_px = 0.0005 * renderer.rig.pixels_per_metre_at_pad()
    radius = 0.4 * spacing_px
    for image, px in ((frame.left, truth.px_left[v]), (frame.right, truth.px_right[v])):
        off = _ink_offsets(image, px, radius)
        assert np.isfinite(off).all()
        assert np.median(off) < 0.3 and off.max() < 1.0, \
            f"{name}: ink centroid offsets median {np.median(off):.3f} max {off.max():.3f} px"
        # the same check fails for centres moved by a third of a glyph spacing
        shifted = _ink_offsets(image, px + [spacing_px / 3, 0], radius)
        assert np.nanmedian(shifted) > 2.0


def test_mirrored_view_flips_columns(artwork_path):
    plain = Renderer(load_artwork(artwork_path), supersample=1)
    mirrored = Renderer(load_artwork(artwork_path), supersample=1, mirrored=True)
    a, b = plain.render([], seed=1).truth, mirrored.render([], seed=1).truth
    i = np.flatnonzero((a.rows == 10) & (a.cols == 2))[0]
    j = np.flatnonzero((b.rows == 10) & (b.cols == 25))[0]
    np.testing.assert_allclose(a.world[i], b.world[j], atol=1e-12)  # cols 2 and 25 swap
    assert a.px_left[i, 0] < 320 < b.px_left[i, 0]
    frame = mirrored.render([], seed=1)
    off = _ink_offsets(frame.left, frame.truth.px_left[frame.truth.visible], 7.0)
    assert np.median(off) < 0.3


def test_rendering_is_deterministic_per_seed(renderer):
    contacts = SCENES["deep_sphere"]
    a = renderer.render(contacts, seed=1, frame_index=2)
    b = renderer.render(contacts, seed=1, frame_index=2)
    c = renderer.render(contacts, seed=2, frame_index=2)
    assert np.array_equal(a.left, b.left) and np.array_equal(a.right, b.right)
    assert not np.array_equal(a.left, c.left)


def test_nuisances_change_the_image_but_not_the_truth(renderer):
    clean = Nuisances(noise_sigma=0, shot_noise=0, blur_sigma=0, vignetting=0)
    harsh = Nuisances(blur_sigma=1.5, noise_sigma=4, shot_noise=0.1, vignetting=0.5, gamma=1.8,
                      exposure=0.7, exposure_jitter=0.1, illumination_gradient=(0.05, -0.03),
                      shadows=[{"x": 0.0, "y": 0.0, "radius": 0.002, "strength": 0.5}],
                      occluders=[{"u": 100, "v": 100, "radius": 20, "strength": 0.5}])
    a = renderer.render([], clean, seed=1)
    b = renderer.render([], harsh, seed=1)
    assert np.abs(a.left.astype(int) - b.left.astype(int)).mean() > 5
    np.testing.assert_array_equal(a.truth.xyz, b.truth.xyz)
    # a strong shadow hides the glyphs under it
    dark = Nuisances(shadows=[{"x": 0.0, "y": 0.0, "radius": 0.002, "strength": 0.95}])
    assert renderer.render([], dark).truth.visible.sum() < a.truth.visible.sum() - 40
    with pytest.raises(ValueError, match="unknown nuisance"):
        Nuisances.from_dict({"blurr": 1})


def test_colour_output(renderer):
    f = renderer.render([], seed=0, color=True)
    assert f.left.shape == (480, 640, 3) and f.left.dtype == np.uint8


def test_glyph_spacing_and_coverage(renderer):
    truth = renderer.render([]).truth
    v = truth.visible
    # neighbours in a row are 16-20 px apart
    idx = {(r, c): i for i, (r, c) in enumerate(zip(truth.rows, truth.cols))}
    d = [np.linalg.norm(truth.px_left[i] - truth.px_left[idx[(r, c + 1)]])
         for i, (r, c) in enumerate(zip(truth.rows, truth.cols)) if v[i] and (r, c + 1) in idx]
    assert 16 <= np.median(d) <= 20
    assert v.sum() >= 600  # the pattern fills most of both images


def test_missing_artwork_is_a_clear_error(tmp_path):
    with pytest.raises(ArtworkError, match="no artwork PNG"):
        load_artwork(tmp_path / "none.png")
    cv2.imwrite(str(tmp_path / "a.png"), np.full((10, 10), 255, np.uint8))
    with pytest.raises(ArtworkError, match="sidecar"):
        load_artwork(tmp_path / "a.png")
    (tmp_path / "a.png.yaml").write_text("cell00_px: [1, 1]\npitch_px: 5\n")
    with pytest.raises(ArtworkError, match="missing key"):
        load_artwork(tmp_path / "a.png")


def test_artwork_drawn_mirrored_is_read_through_its_sidecar(tmp_path, artwork_path):
    import yaml

    png = cv2.imread(str(artwork_path), cv2.IMREAD_GRAYSCALE)
    meta = yaml.safe_load(artwork_path.with_name(artwork_path.name + ".yaml").read_text())
    flipped = tmp_path / "flipped.png"
    cv2.imwrite(str(flipped), png[:, ::-1])
    meta["cell00_px"] = [png.shape[1] - 1 - meta["cell00_px"][0], meta["cell00_px"][1]]
    meta["mirrored"] = True
    flipped.with_name("flipped.png.yaml").write_text(yaml.safe_dump(meta))
    plain = Renderer(load_artwork(artwork_path), supersample=1).render([], seed=2)
    read = Renderer(load_artwork(flipped), supersample=1).render([], seed=2)
    assert np.abs(plain.left.astype(int) - read.left.astype(int)).max() <= 1
