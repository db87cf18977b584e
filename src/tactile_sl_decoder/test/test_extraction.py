"""Glyph extraction on synthetic images with exact ground truth."""
import cv2
import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import cKDTree

from tactile_sl_decoder.contract import PATCH_SIZE
from tactile_sl_decoder.extract import patches as patches_module
from tactile_sl_decoder.extract.extraction import (
    Detections,
    ExtractionParams,
    extract_symbols,
    threshold_ink,
)
from tactile_sl_decoder.extract.patches import sample_patches
from tactile_sl_decoder.extract.spacing import estimate_spacing
from tactile_sl_decoder.tooling.synth_glyphs import finish, render_at, synth_image


def _match(det: Detections, u: np.ndarray, v: np.ndarray, spacing: float):
    dist, _ = cKDTree(np.column_stack((det.u, det.v))).query(np.column_stack((u, v)))
    back, _ = cKDTree(np.column_stack((u, v))).query(np.column_stack((det.u, det.v)))
    return dist, back


@pytest.mark.parametrize("seed,spacing", [(0, 15.0), (1, 18.0), (2, 22.0)])
def test_grid_recall_accuracy_and_spacing(seed, spacing):
    img = synth_image(np.random.default_rng(seed), spacing=spacing)
    det = extract_symbols(img.gray)
    dist, back = _match(det, img.u, img.v, spacing)
    assert (dist < 0.25 * spacing).mean() >= 0.99
    assert np.median(dist) < 0.1  # px: grey-weighted centroids are sub-pixel accurate
    # detections near the truth's region that match nothing would be spurious
    inside = ((det.u > img.u.min()) & (det.u < img.u.max()) & (det.v > img.v.min())
              & (det.v < img.v.max()))
    assert (back[inside] >= 0.25 * spacing).sum() <= 0.01 * inside.sum()
    # warp changes scale by up to ~10 %: the median spacing stays close to nominal
    assert abs(det.spacing_px - spacing) < 0.12 * spacing
    assert det.u.dtype == np.float32 and det.v.dtype == np.float32
    assert det.area.dtype == np.float32 and len(det.area) == len(det)
    assert det.patches.shape == (len(det), PATCH_SIZE, PATCH_SIZE)
    assert det.patches.dtype == np.uint8


def _touching_groups(sep: float, spacing: float, seed: int):
    """A sparse grid of single glyphs plus pairs and triples whose glyphs touch."""
    rng = np.random.default_rng(seed)
    shape = (480, 640)
    gy, gx = np.mgrid[1:480 // int(spacing), 1:640 // int(spacing)]
    grid = np.column_stack([gx.ravel() * spacing, gy.ravel() * spacing])
    free = np.ones(len(grid), bool)
    layouts = {"pair_h": [(0, 0), (1, 0)], "pair_v": [(0, 0), (0, 1)],
               "pair_diag": [(0, 0), (0.7, 0.7)], "triple_h": [(-1, 0), (0, 0), (1, 0)],
               "triple_v": [(0, -1), (0, 0), (0, 1)], "triple_l": [(0, 0), (1, 0), (1, 1)]}
    groups = []
    for i, (_, offsets) in enumerate(list(layouts.items()) * 3):
        cx = (4 + 5 * (i % 6)) * spacing
        cy = (4 + 5 * (i // 6)) * spacing
        if cx > 600 or cy > 440:
            continue
        free &= np.hypot(grid[:, 0] - cx, grid[:, 1] - cy) > 2.2 * spacing
        groups.append(np.array([(cx + a * sep * spacing, cy + b * sep * spacing)
                                for a, b in offsets]))
    centres = np.vstack([grid[free], *groups])
    cover = render_at(centres, rng.integers(0, 3, len(centres)), spacing, shape)
    for g in groups:  # a thin ink link guarantees contact whatever the shapes
        for a, b in zip(g[:-1], g[1:]):
            line = np.zeros(shape, np.uint8)
            cv2.line(line, tuple(int(8 * x) for x in a), tuple(int(8 * x) for x in b), 255, 1,
                     lineType=cv2.LINE_AA, shift=3)
            cover = np.maximum(cover, line.astype(np.float32) / 255.0)
    gray = finish(cover, rng, blur=0.9, noise=2.0, gradient=0.2)
    labels, _ = ndimage.label(threshold_ink(gray, ExtractionParams()) > 0,
                              structure=np.ones((3, 3)))
    for g in groups:  # the premise of the test: every group is one blob for the extractor
        ids = {labels[int(round(y)), int(round(x))] for x, y in g}
        assert len(ids) == 1 and 0 not in ids
    return gray, centres, groups


@pytest.mark.slow
@pytest.mark.parametrize("sep,spacing,seed", [(0.55, 18.0, 0), (0.6, 22.0, 1),
                                              (0.7, 16.0, 2), (0.6, 14.0, 3)])
def test_linked_pairs_and_triples_are_split(sep, spacing, seed):
    gray, centres, groups = _touching_groups(sep, spacing, seed)
    det = extract_symbols(gray)
    tree = cKDTree(np.column_stack((det.u, det.v)))
    for g in groups:
        dist, idx = tree.query(g)
        assert (dist < 0.25 * spacing).all(), (g, dist / spacing)
        assert len(set(idx.tolist())) == len(g)  # one detection per glyph, not shared
    back, _ = cKDTree(centres).query(np.column_stack((det.u, det.v)))
    assert (back >= 0.25 * spacing).sum() == 0  # no phantom glyph between linked ones
    assert len(det) == len(centres)


@pytest.mark.parametrize("sep,spacing,seed", [(0.55, 18.0, 0), (0.6, 22.0, 1),
                                              (0.7, 16.0, 2), (0.6, 14.0, 3)])
def test_centroid_of_split_glyphs_does_not_pull_towards_the_linked_neighbour(sep, spacing,
                                                                           seed):
    gray, _, groups = _touching_groups(sep, spacing, seed)
    truth = np.concatenate([np.asarray(g) for g in groups])
    rms = []
    for passes in (0, 1):
        det = extract_symbols(gray, ExtractionParams(refine_split=passes))
        dist, _ = cKDTree(np.column_stack((det.u, det.v))).query(truth)
        rms.append(float(np.sqrt(np.mean(dist ** 2))))
    assert rms[1] <= rms[0] + 0.02, rms    # px; a 0.45 disc made it 1.2-2.2 px


def test_blank_and_degenerate_images():
    for gray in (np.full((480, 640), 128, np.uint8), np.zeros((0, 0), np.uint8),
                 np.zeros((5, 5), np.uint8)):
        det = extract_symbols(gray)
        assert len(det) == 0 and det.patches.shape == (0, PATCH_SIZE, PATCH_SIZE)
        assert det.spacing_px == 0.0
    with pytest.raises(ValueError):
        extract_symbols(np.zeros((10, 10), np.float32))
    with pytest.raises(ValueError):
        extract_symbols(np.zeros((10, 10, 3), np.uint8))


def test_bright_glyphs_with_inverted_polarity():
    img = synth_image(np.random.default_rng(3), spacing=18.0)
    det = extract_symbols(255 - img.gray, ExtractionParams(dark_glyphs=False))
    dist, _ = _match(det, img.u, img.v, 18.0)
    assert (dist < 0.25 * 18.0).mean() >= 0.99


def test_patch_scale_follows_spacing():
    """The same glyphs at 14 and 26 px spacing give patches with the same ink share."""
    shares = []
    for spacing in (14.0, 26.0):
        img = synth_image(np.random.default_rng(4), spacing=spacing, warp_strength=0.0,
                          blur=0.6, noise=1.0, gradient=0.0)
        det = extract_symbols(img.gray)
        p = det.patches.reshape(len(det), -1).astype(np.float32)
        dark = p < (p.max(axis=1, keepdims=True) + p.min(axis=1, keepdims=True)) / 2
        shares.append(dark.mean())
        assert abs(np.median(det.local_spacing) - spacing) < 0.1 * spacing
    assert abs(shares[0] - shares[1]) < 0.15 * shares[0]


def test_sample_patches_centre_and_border():
    gray = np.zeros((40, 60), np.uint8)
    gray[20, 30] = 255
    p = sample_patches(gray, np.array([30.0, 0.0], np.float32), np.array([20.0, 0.0],
                                                                         np.float32),
                       np.array([1.0, 1.0], np.float32))
    assert p.shape == (2, PATCH_SIZE, PATCH_SIZE)
    # 18 px patch centred on a pixel: the centre lies between patch pixels 8 and 9
    assert p[0, 8:10, 8:10].sum() > 0 and p[0].sum() == p[0, 8:10, 8:10].sum()
    many = sample_patches(gray, np.full(2000, 30.0, np.float32), np.full(2000, 20.0,
                                                                         np.float32),
                          np.ones(2000, np.float32))  # more than one remap chunk
    assert (many == p[0]).all()


def test_square_patch_kernel_gives_opencv_bytes():
    """The kernel behind sample_patches is cv2.remap bit for bit (borders, ties, any scale)."""
    assert patches_module._kernel_is_exact()      # else every call would go to cv2.remap
    rng = np.random.default_rng(11)
    for h, w in ((1, 1), (2, 3), (48, 64), (480, 640)):
        gray = rng.integers(0, 256, (h, w), dtype=np.uint8)
        n = 300
        u = rng.uniform(-12.0, w + 12.0, n).astype(np.float32)
        v = rng.uniform(-12.0, h + 12.0, n).astype(np.float32)
        v[:50] = np.round(v[:50] * 32.0) / 32.0       # exactly on OpenCV's 1/32 grid
        u[50:100] = np.floor(u[50:100]) + 0.5        # half-way: rounding ties
        step = rng.uniform(0.3, 3.0, n).astype(np.float32)
        gray.flags.writeable = bool(h % 2)            # read-only images (from a bag) too
        np.testing.assert_array_equal(sample_patches(gray, u, v, step),
                                      patches_module.remap_patches(gray, u, v, step))


def test_spacing_estimate_on_a_lattice():
    gy, gx = np.mgrid[0:20, 0:30]
    u = (gx.ravel() * 17.0).astype(np.float32)
    v = (gy.ravel() * 17.0).astype(np.float32)
    spacing, local = estimate_spacing(u, v, search_px=25.0)
    assert spacing == pytest.approx(17.0, abs=1e-3)
    assert np.allclose(local, 17.0, atol=1e-3)
    spacing2, local2 = estimate_spacing(u, v)  # k-nearest path
    assert spacing2 == pytest.approx(17.0, abs=1e-3) and np.allclose(local2, 17.0, atol=1e-3)
    assert estimate_spacing(u[:1], v[:1])[0] == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("offset", [-2.0, 0.0, 0.5, 1.0, 7.5, 8.0, 20.0])
@pytest.mark.parametrize("dark", [True, False])
def test_threshold_matches_cv2_adaptive_threshold(offset, dark):
    gray = synth_image(np.random.default_rng(3), spacing=17.0).gray
    gray = gray if dark else 255 - gray
    params = ExtractionParams(offset=offset, dark_glyphs=dark, open_size=1)
    mode = cv2.THRESH_BINARY_INV if dark else cv2.THRESH_BINARY
    ref = cv2.adaptiveThreshold(gray, 255, cv2.ADAPTIVE_THRESH_MEAN_C, mode,
                                params.block_size, offset if dark else -offset)
    np.testing.assert_array_equal(threshold_ink(gray, params), ref)


@pytest.mark.slow
@pytest.mark.parametrize("x0,y0,w,h", [(0, 0, 640, 480), (37, 11, 301, 200),
                                       (116, 0, 524, 480), (3, 5, 77, 101)])
def test_ink_box_labels_like_the_whole_image(x0, y0, w, h):
    """Labelling only the (even-aligned) ink box gives the same regions in the same order."""
    from tactile_sl_decoder.extract.extraction import _ink_box

    gray = np.ascontiguousarray(synth_image(np.random.default_rng(4), spacing=16.0).gray[
        y0:y0 + h, x0:x0 + w])
    gray[:, : w // 5] = 210  # blank margin: the box no longer spans the image
    mask = threshold_ink(gray, ExtractionParams())
    n, _, stats, cent = cv2.connectedComponentsWithStats(mask, connectivity=8)
    ox, oy, roi = _ink_box(mask)
    assert ox % 2 == 0 and oy % 2 == 0 and roi.shape[0] % 2 == 0 and roi.shape[1] % 2 == 0
    n2, _, stats2, cent2 = cv2.connectedComponentsWithStats(roi, connectivity=8)
    assert n2 == n
    np.testing.assert_array_equal(stats2[1:, cv2.CC_STAT_AREA], stats[1:, cv2.CC_STAT_AREA])
    np.testing.assert_allclose(cent2[1:] + (ox, oy), cent[1:], atol=1e-9)


def _glyph_grid(rng: np.random.Generator, spacing: float, shift=(0.0, 0.0)):
    """Glyph centres on a square lattice over a 640 x 480 image and their ink coverage."""
    gy, gx = np.mgrid[1:480 // int(spacing), 1:640 // int(spacing)]
    centres = np.column_stack([gx.ravel() * spacing + shift[0], gy.ravel() * spacing + shift[1]])
    return centres, render_at(centres, rng.integers(0, 3, len(centres)), spacing, (480, 640))


def _striped_object(seed: int, angle_deg: float, spacing: float = 18.0):
    """Glyphs with a striped object seen through the pad between them (a disc of 5.5
    spacings): stripes of 0.4 spacing at a 0.8 spacing period, darker (50) than the gaps
    (140) and the paper (180), lighter than the ink (20), as in the sweep's object_stripes."""
    rng = np.random.default_rng(seed)
    centres, cover = _glyph_grid(rng, spacing, (3.0, 2.0))
    yy, xx = np.mgrid[0:480, 0:640].astype(np.float32)
    radius = 5.5 * spacing
    inside = np.hypot(xx - 320, yy - 240) < radius
    t = np.radians(angle_deg)
    phase = ((xx * np.cos(t) + yy * np.sin(t)) / (0.8 * spacing)) % 1.0
    albedo = np.where(inside, np.where(phase < 0.5, 50.0, 140.0), 180.0).astype(np.float32)
    img = cv2.GaussianBlur(albedo, (0, 0), 0.7) * (1 - cover) + 20.0 * cover
    img = cv2.GaussianBlur(img, (0, 0), 1.0) + rng.normal(0, 1.5, img.shape)
    on_object = np.hypot(centres[:, 0] - 320, centres[:, 1] - 240) < radius - 0.5 * spacing
    return np.clip(img, 0, 255).astype(np.uint8), centres, on_object


@pytest.mark.parametrize("seed,angle", [(0, 60.0), (1, 30.0), (2, -45.0)])
def test_glyphs_crossed_by_stripes_are_recovered(seed, angle):
    gray, centres, on = _striped_object(seed, angle)
    spacing = 18.0
    found, dist = {}, {}
    for split in (False, True):
        det = extract_symbols(gray, ExtractionParams(split_linked_large=split))
        dist[split], back = _match(det, centres[:, 0], centres[:, 1], spacing)
        found[split] = dist[split] < 0.25 * spacing
        assert (back >= 0.25 * spacing).sum() == 0          # no stripe piece as a glyph
        assert found[split][~on].mean() >= 0.95
    # glyph and stripe ink form long regions: without the split the glyphs on the object
    # are lost (the premise), with it they are found
    assert found[False][on].mean() < 0.2
    assert found[True][on].mean() >= 0.97
    # their centres lean towards the stripe they overlap (docstring of
    # _glyphs_in_linked_parts), by about a pixel, far less than the 0.25 spacing gate
    assert np.median(dist[True][on & found[True]]) < 1.3


def _lit_grid(seed: int, light_on: bool, spacing: float = 18.0):
    """Glyph grid under a hot spot's fall-off and a soft shadow (or uniform light)."""
    rng = np.random.default_rng(seed)
    centres, cover = _glyph_grid(rng, spacing, (0.3, 0.6))
    light = np.ones((480, 640), np.float32)
    if light_on:
        yy, xx = np.mgrid[0:480, 0:640].astype(np.float32)
        light = 0.35 + 0.65 * np.clip(np.hypot(xx - 150, yy - 120) / 500.0, 0, 1) ** 0.5
        light *= 1.0 - 0.5 * np.exp(-((xx - 420) ** 2 + (yy - 300) ** 2) / (2 * 45.0 ** 2))
    img = cv2.GaussianBlur(light * (200.0 - 170.0 * cover), (0, 0), 1.2)
    img = img + rng.normal(0, 1.0, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8), centres


@pytest.mark.parametrize("seed", [0, 1])
def test_centroid_is_not_pulled_by_uneven_light(seed):
    rms = {}
    for light_on in (False, True):
        gray, centres = _lit_grid(seed, light_on)
        for flatten in (False, True):
            det = extract_symbols(gray, ExtractionParams(centroid_flatten=flatten))
            dist, _ = _match(det, centres[:, 0], centres[:, 1], 18.0)
            assert (dist < 4.5).all()
            rms[light_on, flatten] = float(np.sqrt(np.mean(dist ** 2)))
    # the light's gradients add ~0.013 px rms to the flat-mean centroid (the premise) ...
    added_flat = rms[True, False] - rms[False, False]
    assert added_flat > 0.008, rms
    # ... and a fraction of that to the one weighted from the background's plane (measured
    # +0.003: a few patches whose border is no plane keep the flat mean)
    assert rms[True, True] - rms[False, True] < 0.4 * added_flat, rms
    assert rms[True, True] < rms[True, False] - 0.015, rms


def test_the_extractor_config_lists_every_extraction_parameter_with_its_default():
    """config/symbol_extractor.yaml shows users every knob (it once missed seven)."""
    import dataclasses

    import yaml

    from ros_harness import REPO

    doc = yaml.safe_load((REPO / "src" / "tactile_sl_decoder" / "config" /
                          "symbol_extractor.yaml").read_text())
    values = doc["/**/symbol_extractor"]["ros__parameters"]
    for f in dataclasses.fields(ExtractionParams):
        assert f.name in values, f.name
        assert values[f.name] == f.default, (f.name, values[f.name], f.default)


def _dark_object(seed: int, spacing: float = 18.0):
    """Glyphs with a dark object seen through the pad between them (a disc of 5.3 spacings,
    albedo 70 against the paper's 190, the ink 20): its rim crosses glyph patches."""
    rng = np.random.default_rng(seed)
    centres, cover = _glyph_grid(rng, spacing, (3.0, 2.0))
    yy, xx = np.mgrid[0:480, 0:640].astype(np.float32)
    radius = 5.3 * spacing
    albedo = np.where(np.hypot(xx - 320, yy - 240) < radius, 70.0, 190.0).astype(np.float32)
    img = cv2.GaussianBlur(albedo, (0, 0), 0.7) * (1 - cover) + 20.0 * cover
    img = cv2.GaussianBlur(img, (0, 0), 1.2) + rng.normal(0, 1.0, img.shape)
    rim = np.abs(np.hypot(centres[:, 0] - 320, centres[:, 1] - 240) - radius)
    return np.clip(img, 0, 255).astype(np.uint8), centres, rim


@pytest.mark.parametrize("seed", [0, 1])
def test_centroid_at_a_dark_objects_rim_follows_the_background(seed):
    gray, centres, rim = _dark_object(seed)
    spacing = 18.0
    err = {}
    for follow in (False, True):
        det = extract_symbols(gray, ExtractionParams(centroid_background=follow))
        dist, _ = _match(det, centres[:, 0], centres[:, 1], spacing)
        err[follow] = dist
    near = rim < 0.45 * spacing            # the rim crosses the glyph's patch
    far = rim > 1.5 * spacing
    assert near.sum() >= 10 and far.sum() >= 200
    found = err[False] < 0.25 * spacing
    # a flat mean counts the object's dark side as ink (the premise: centres pulled by
    # about a pixel, measured 1.35 px rms); the threshold that follows the background
    # about halves that (measured 0.68 px)
    rms = {k: float(np.sqrt(np.mean(e[near & found] ** 2))) for k, e in err.items()}
    assert rms[False] > 0.5, rms
    assert rms[True] < 0.6 * rms[False], rms
    # glyphs away from the rim: the same centres
    np.testing.assert_array_equal(err[True][far], err[False][far])
