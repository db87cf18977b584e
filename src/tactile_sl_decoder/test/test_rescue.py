"""Glyphs one camera did not detect, measured where the other camera's cells put them
(stereo/rescue.py), and the pipeline using them."""
import copy

import cv2
import numpy as np
import pytest

from tactile_sl_common.images import to_gray
from tactile_sl_decoder.contract import LABEL_UNKNOWN
from tactile_sl_decoder.extract.extraction import Detections, ExtractionParams, extract_symbols
from tactile_sl_decoder.frames import bag_frames
from tactile_sl_decoder.glyphs import Glyphs
from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline
from tactile_sl_decoder.stereo.rescue import RescueParams, ink_contrast, rescue_pair
from tactile_sl_decoder.tooling.e2e_metrics import frame_metrics

from ros_harness import REPO

BAG = REPO / "bags" / "sphere_deep_small.mcap"
# a 5 x 6 block of cells over the pressed sphere's flank (the disparity changes fastest there)
ROWS, COLS = (10, 15), (12, 18)


@pytest.fixture(scope="module")
def pressed():
    """A frame of a deep, small sphere: images, infos, truth, decoded glyphs, classifier."""
    frame = list(bag_frames(BAG))[4]
    images = (to_gray(frame.left_image), to_gray(frame.right_image), frame.left_info,
              frame.right_info)
    pipe = StereoPipeline(PatternSpec.load(), params=PipelineParams(threads=1))
    result = pipe.process(*images)
    predict = pipe.load_classifier().predict
    pipe.close()
    return images, frame.ground_truth, result, pipe.pattern.array, predict


def _without(g: Glyphs, gone: np.ndarray) -> Glyphs:
    """``g`` with the glyphs where ``gone`` is true left out (never detected)."""
    keep = np.flatnonzero(~gone)
    out = Glyphs(g.u[keep], g.v[keep], g.label[keep], g.confidence[keep], g.spacing_px,
                 g.image_width, g.image_height, g.area[keep], g.patches[keep])
    out.row, out.col = g.row[keep].copy(), g.col[keep].copy()
    return out


def _without_block(g: Glyphs) -> tuple[Glyphs, np.ndarray]:
    """``g`` without the glyphs of the block's cells; their indices."""
    hit = (g.row >= ROWS[0]) & (g.row < ROWS[1]) & (g.col >= COLS[0]) & (g.col < COLS[1])
    return _without(g, hit), np.flatnonzero(hit)


def test_undetected_glyphs_are_measured_where_the_other_camera_puts_them(pressed):
    (left_img, right_img, _li, _ri), _truth, result, symbols, predict = pressed
    ncols = symbols.shape[1]
    right, hit = _without_block(result.right)
    assert len(hit) == 30
    found_left, found_right = rescue_pair(result.left, right, (left_img, right_img), symbols,
                                          ExtractionParams(), predict)
    assert len(found_left.cell) == 0              # the left image lacks none of its cells
    clean = result.right
    expected = clean.row[hit].astype(np.int64) * ncols + clean.col[hit]
    np.testing.assert_array_equal(np.sort(found_right.cell), np.sort(expected))
    # at the centre the extractor itself measures there (same centroid, other start)
    order = np.argsort(found_right.cell)
    where = hit[np.argsort(expected)]
    err = np.hypot(found_right.uv[order, 0] - clean.u[where],
                   found_right.uv[order, 1] - clean.v[where])
    assert err.max() < 0.1
    symbol = symbols.reshape(-1)[found_right.cell]
    assert np.all((found_right.label == LABEL_UNKNOWN) | (found_right.label == symbol))


def test_a_glyph_without_ink_is_not_rescued(pressed):
    """Worn off: the block's glyphs painted over with the pad's background."""
    (left_img, right_img, _li, _ri), _truth, result, symbols, predict = pressed
    right, hit = _without_block(result.right)
    blank = right_img.copy()
    mask = np.zeros_like(blank)
    s = int(round(0.45 * result.right.spacing_px))
    for u, v in zip(result.right.u[hit], result.right.v[hit]):
        cv2.circle(mask, (int(round(u)), int(round(v))), s, 255, -1)
    blank = cv2.inpaint(blank, mask, 3, cv2.INPAINT_TELEA)
    _, found = rescue_pair(result.left, right, (left_img, blank), symbols, ExtractionParams(),
                           predict)
    assert len(found.cell) == 0
    # the contrast measure that refuses them: blank patches have next to none
    assert np.median(ink_contrast(result.right.patches)) > 0.2


def test_a_contradicting_reading_or_too_few_neighbours_refuse(pressed):
    (left_img, right_img, _li, _ri), _truth, result, symbols, predict = pressed
    right, hit = _without_block(result.right)
    images = (left_img, right_img)

    def reads(value):
        return lambda patches: (np.full(len(patches), value, np.uint8),
                                np.ones(len(patches), np.float32))

    # a reader that always says one symbol contradicts every cell of another symbol: only
    # cells of its symbol are measured (and the growth stops at the others)
    for value in np.unique(symbols[result.right.row[hit], result.right.col[hit]]):
        _, found = rescue_pair(result.left, right, images, symbols, ExtractionParams(),
                               reads(int(value)))
        assert len(found.cell) > 0
        assert np.all(symbols.reshape(-1)[found.cell] == value)
    _, found = rescue_pair(result.left, right, images, symbols, ExtractionParams(),
                           reads(LABEL_UNKNOWN))
    assert len(found.cell) == len(hit)
    # all 8 neighbours required: no cell of the block has them (each borders another
    # missing one), a lone missing glyph has
    _, found = rescue_pair(result.left, right, images, symbols, ExtractionParams(), predict,
                           RescueParams(min_neighbours=8))
    assert len(found.cell) == 0
    g = result.right
    alone = _without(g, (g.row == 20) & (g.col == 20))
    _, found = rescue_pair(result.left, alone, images, symbols, ExtractionParams(), predict,
                           RescueParams(min_neighbours=8))
    assert list(found.cell) == [20 * symbols.shape[1] + 20]
    _, found = rescue_pair(result.left, right, images, symbols, ExtractionParams(), predict,
                           RescueParams(enabled=False))
    assert len(found.cell) == 0


def test_params_are_checked():
    RescueParams().validate()
    for bad in (dict(radius=0.0), dict(radius=0.5), dict(clearance=0.05),
                dict(min_neighbours=0), dict(min_neighbours=9), dict(min_contrast=-0.1),
                dict(centroid_passes=0), dict(grow_passes=-1)):
        with pytest.raises(ValueError):
            RescueParams(**bad).validate()
    with pytest.raises(ValueError):
        StereoPipeline(PatternSpec.load(), params=PipelineParams(
            threads=1, rescue=RescueParams(radius=2.0)))


class _BlindPatch:
    """Extractor that loses every glyph in a 150 x 150 px square of every second image
    (the right one: the pipeline extracts left, then right, on one thread)."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, gray: np.ndarray, params: ExtractionParams) -> Detections:
        det = extract_symbols(gray, params)
        self.calls += 1
        if self.calls % 2:
            return det
        keep = ~((det.u > 150) & (det.u < 300) & (det.v > 250) & (det.v < 400))
        return Detections(det.u[keep], det.v[keep], det.area[keep], det.spacing_px,
                          det.patches[keep], det.local_spacing[keep])


def test_the_pipeline_measures_a_patch_one_camera_misses(pressed):
    """Through the pipeline: the points of a patch the right camera found no glyph in come
    back with rescue on, each as near the truth as the others."""
    (left, right, li, ri), truth, clean, _symbols, _predict = pressed
    tol = 0.5 * PatternSpec.load().pitch_m
    out = {}
    for enabled in (False, True):
        params = PipelineParams(threads=1)
        params.rescue.enabled = enabled
        pipe = StereoPipeline(PatternSpec.load(), params=params, extractor=_BlindPatch())
        out[enabled] = pipe.process(left, right, li, ri)
        pipe.close()
    off, on = (frame_metrics(out[k].points, truth, tol) for k in (False, True))
    every = frame_metrics(clean.points, truth, tol)
    assert off.correct < every.correct - 50          # the patch's points are lost ...
    assert on.correct >= every.correct - 5           # ... and come back
    assert on.wrong == 0
    assert np.sqrt(np.mean(on.errors_m ** 2)) < 1.5 * np.sqrt(np.mean(every.errors_m ** 2))
    assert len(out[True].right) == len(out[False].right)   # the glyph arrays stay as found
    # reported per image (the decoder's diagnostics name the camera that needed help)
    assert out[True].assisted[0] == 0 and out[True].assisted[1] >= on.correct - off.correct
    assert out[False].assisted == (0, 0)


def test_the_symbols_path_does_not_rescue(pressed):
    """process_symbols has no images: it triangulates what the glyph arrays hold."""
    (_left, _right, li, ri), _truth, result, _symbols, _predict = pressed
    right, _hit = _without_block(result.right)
    pipe = StereoPipeline(PatternSpec.load(), params=PipelineParams(threads=1))
    res = pipe.process_symbols(copy.deepcopy(result.left), right, li, ri)
    pipe.close()
    assert len(res.points) < len(result.points) - 25
