"""Cells carried across the stereo pair (stereo/transfer.py) and the pipeline using them."""
import copy

import numpy as np
import pytest

from tactile_sl_common.images import to_gray
from tactile_sl_decoder.contract import CELL_UNKNOWN, LABEL_UNKNOWN
from tactile_sl_decoder.frames import bag_frames
from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline
from tactile_sl_decoder.stereo.stereo import StereoRig
from tactile_sl_decoder.stereo.transfer import TransferParams, transfer_cells

from ros_harness import REPO

BAG = REPO / "bags" / "sphere_deep_small.mcap"


@pytest.fixture(scope="module")
def pressed():
    """A frame of a deep, small sphere: images, infos, truth, and its decoded glyphs."""
    frame = list(bag_frames(BAG))[4]
    images = (to_gray(frame.left_image), to_gray(frame.right_image), frame.left_info,
              frame.right_info)
    params = PipelineParams(threads=1)
    params.transfer.enabled = False
    pipe = StereoPipeline(PatternSpec.load(), params=params)
    result = pipe.process(*images)
    rig = pipe.rig(frame.left_info, frame.right_info)
    rect = [StereoRig.rectify(cam, np.column_stack([g.u, g.v]))
            for cam, g in ((rig.left, result.left), (rig.right, result.right))]
    pipe.close()
    return images, frame.ground_truth, result, rect, pipe.pattern.array


def _erase_block(glyphs, rows, cols, unknown_labels=True):
    """Copy of ``glyphs`` with the cells of a block taken away; the erased indices."""
    g = copy.deepcopy(glyphs)
    hit = np.flatnonzero((g.row >= rows[0]) & (g.row < rows[1]) & (g.col >= cols[0])
                         & (g.col < cols[1]))
    g.row[hit] = CELL_UNKNOWN
    g.col[hit] = CELL_UNKNOWN
    if unknown_labels:
        g.label[hit] = LABEL_UNKNOWN
    return g, hit


def test_cells_one_image_lost_come_back_from_the_other(pressed):
    _images, _truth, result, rect, symbols = pressed
    # a 5 x 6 block over the pressed sphere's flank (the disparity changes fastest there)
    rows, cols = (10, 15), (12, 18)
    right, hit = _erase_block(result.right, rows, cols)
    assert len(hit) == 30
    n = transfer_cells(result.left, right, rect[0], rect[1], symbols)
    assert n == len(hit)
    np.testing.assert_array_equal(right.row, result.right.row)
    np.testing.assert_array_equal(right.col, result.right.col)
    # the other way round as well, with the labels kept (they are the pattern's symbols)
    left, hit = _erase_block(result.left, rows, cols, unknown_labels=False)
    assert transfer_cells(left, result.right, rect[0], rect[1], symbols) == len(hit)
    np.testing.assert_array_equal(left.row, result.left.row)


def test_a_contradicting_label_a_crowded_place_or_too_few_neighbours_refuse(pressed):
    _images, _truth, result, rect, symbols = pressed
    right, hit = _erase_block(result.right, (12, 13), (14, 15))
    (i,) = hit
    cell = (int(result.right.row[i]), int(result.right.col[i]))
    # a confident label that is not the pattern's symbol of the cell
    wrong = copy.deepcopy(right)
    wrong.label[i] = (int(symbols[cell]) + 1) % 3
    assert transfer_cells(result.left, wrong, rect[0], rect[1], symbols) == 0
    assert wrong.row[i] == CELL_UNKNOWN
    # another glyph a third of a spacing away: which one is the glyph is in doubt
    spacing = right.spacing_px
    crowded_rect = rect[1].copy()
    far = int(np.argmax(np.hypot(*(rect[1] - rect[1][i]).T)))
    crowded_rect[far] = rect[1][i] + (0.33 * spacing, 0.0)
    assert transfer_cells(result.left, copy.deepcopy(right), rect[0], crowded_rect,
                          symbols) == 0
    # the glyph is not where the neighbours put it (moved by 0.4 spacing): nothing given
    moved_rect = rect[1].copy()
    moved_rect[i] += (0.4 * spacing, 0.0)
    assert transfer_cells(result.left, copy.deepcopy(right), rect[0], moved_rect,
                          symbols) == 0
    # every neighbour erased as well: nothing to predict the centre from in one pass (the
    # ring around it comes back, each from its neighbours outside); in a second pass it can
    alone, _ = _erase_block(result.right, (11, 14), (13, 16))
    assert transfer_cells(result.left, alone, rect[0], rect[1], symbols,
                          TransferParams(passes=1)) == 8
    assert alone.row[i] == CELL_UNKNOWN
    assert transfer_cells(result.left, alone, rect[0], rect[1], symbols,
                          TransferParams(passes=1)) == 1
    assert (alone.row[i], alone.col[i]) == cell


def test_params_are_checked():
    TransferParams().validate()
    for bad in (dict(radius=0.0), dict(radius=0.5), dict(clearance=0.05),
                dict(min_neighbours=0), dict(min_neighbours=9), dict(passes=-1)):
        with pytest.raises(ValueError):
            TransferParams(**bad).validate()
    with pytest.raises(ValueError):
        StereoPipeline(PatternSpec.load(), params=PipelineParams(
            threads=1, transfer=TransferParams(radius=2.0)))


def test_a_region_one_camera_sees_badly_is_measured_through_the_other(pressed):
    """A quarter of the right image smeared (each glyph a blob, as through a smudge on that
    lens): without the transfer many of its cells are lost; with it part of them come back,
    each glyph with the cell it has in the clean image (blobs that read as another symbol
    stay out)."""
    import cv2
    from scipy.spatial import cKDTree

    (left, right, li, ri), _truth, clean, _rect, _symbols = pressed
    dim = right.copy()
    dim[240:, :320] = cv2.GaussianBlur(cv2.erode(dim[240:, :320], np.ones((7, 7), np.uint8)),
                                       (0, 0), 1.0)
    out = {}
    for enabled in (False, True):
        params = PipelineParams(threads=1)
        params.transfer.enabled = enabled
        pipe = StereoPipeline(PatternSpec.load(), params=params)
        out[enabled] = pipe.process(left, dim, li, ri)
        pipe.close()
    assert len(out[True].points) >= len(out[False].points) + 20
    assert out[True].assisted[1] >= 20 and out[True].assisted[0] <= 2   # the smeared camera
    for result in out.values():
        g = result.right
        has = np.flatnonzero(g.row >= 0)
        dist, near = cKDTree(np.column_stack([clean.right.u, clean.right.v])).query(
            np.column_stack([g.u[has], g.v[has]]))
        same_place = dist < 0.3 * g.spacing_px
        assert same_place.mean() > 0.98
        np.testing.assert_array_equal(g.row[has][same_place], clean.right.row[near][same_place])
        np.testing.assert_array_equal(g.col[has][same_place], clean.right.col[near][same_place])
