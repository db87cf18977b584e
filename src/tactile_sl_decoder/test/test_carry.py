"""Labels carried from the previous frame (classify/carry.py) and the pipeline using them."""
import numpy as np
import pytest

from tactile_sl_common.images import to_gray
from tactile_sl_decoder.classify.carry import CarryParams, LabelCarry
from tactile_sl_decoder.contract import LABEL_UNKNOWN, PATCH_SIZE
from tactile_sl_decoder.frames import bag_frames
from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline

from ros_harness import REPO

BAG = REPO / "bags" / "sphere_deep_small.mcap"


@pytest.fixture(scope="module")
def frames():
    """(left grey, right grey, left info, right info, ground truth) of the bag's frames."""
    return [(to_gray(f.left_image), to_gray(f.right_image), f.left_info, f.right_info)
            for f in bag_frames(BAG)]


def _pipelines(carry_on_params: CarryParams | None = None):
    off = PipelineParams(threads=1)
    off.carry.enabled = False
    on = PipelineParams(threads=2)
    on.carry = carry_on_params or CarryParams()
    spec = PatternSpec.load()
    return StereoPipeline(spec, params=off), StereoPipeline(spec, params=on)


def _lattice_step(result) -> np.ndarray:
    """Median pixel step from a decoded glyph to the one at the next column (left image)."""
    g = result.left
    key = {(int(r), int(c)): i for i, (r, c) in enumerate(zip(g.row, g.col)) if r >= 0}
    steps = [(g.u[j] - g.u[i], g.v[j] - g.v[i]) for (r, c), i in key.items()
             if (j := key.get((r, c + 1))) is not None]
    return np.median(np.asarray(steps), axis=0)


def test_static_frames_keep_their_labels_and_points(frames):
    off, on = _pipelines()
    first = on.process(*frames[0])
    assert first.carried == 0                       # nothing to carry from
    again = on.process(*frames[0])
    fresh = off.process(*frames[0])
    n = len(again.left) + len(again.right)
    # all but the glyphs due for their regular re-classification (1 in refresh_frames)
    assert again.carried >= 0.8 * n
    np.testing.assert_array_equal(again.left.label, fresh.left.label)
    np.testing.assert_array_equal(again.right.label, fresh.right.label)
    assert again.points.tobytes() == fresh.points.tobytes()
    on.close()
    off.close()


def test_jumps_loops_and_one_glyph_shifts_give_the_points_of_no_carrying(frames):
    """Carrying never changes a cell: a whole-pitch shift, a sudden press, a loop back.

    Labels and cells (decode/track.py) are carried where they can be; the points must be
    those of a pipeline that classifies and decodes every frame in full.
    """
    off, on = _pipelines()
    base = off.process(*frames[0])
    step = _lattice_step(base)
    shift = np.rint(step).astype(int)
    assert 10 <= abs(shift[0]) <= 30             # one glyph spacing along the columns

    def shifted(frame, by):
        left, right, li, ri = frame
        return (np.roll(left, (by[1], by[0]), axis=(0, 1)),
                np.roll(right, (by[1], by[0]), axis=(0, 1)), li, ri)

    half = np.rint(0.5 * step).astype(int)
    sequence = [frames[0], frames[0], shifted(frames[0], shift), frames[0], frames[3],
                frames[3], frames[0], shifted(frames[0], half), frames[6], frames[6]]
    carried, tracked = [], []
    for frame in sequence:
        a, b = off.process(*frame), on.process(*frame)
        assert a.points.tobytes() == b.points.tobytes()
        carried.append(b.carried)
        tracked.append(b.tracked)
    assert carried[1] > 0 and carried[5] > 0 and carried[9] > 0
    # cells carried on the repeated frame, never across a shift by one or half a spacing
    # (there or back); after the press they may be, where the lattice confirms every cell
    assert tracked[1], tracked
    assert not any(tracked[i] for i in (0, 2, 3, 7)), tracked
    on.close()
    off.close()


def _patch(kind: str) -> np.ndarray:
    p = np.full((PATCH_SIZE, PATCH_SIZE), 200, np.uint8)
    c = PATCH_SIZE // 2
    if kind == "line":
        p[c - 1:c + 2, 4:PATCH_SIZE - 4] = 30
    elif kind == "circle":
        yy, xx = np.mgrid[:PATCH_SIZE, :PATCH_SIZE]
        ring = np.abs(np.hypot(yy - c + 0.5, xx - c + 0.5) - 4.5) < 1.3
        p[ring] = 30
    elif kind == "triangle":
        for r in range(5, 13):
            half = (r - 5) // 2 + 1
            p[r, c - half:c + half] = 30
    return p


def test_a_glyph_that_moved_too_far_or_changed_its_look_is_classified_again():
    carry = LabelCarry(CarryParams(refresh_frames=100))
    u = np.array([20.0, 40.0, 60.0, 80.0])
    v = np.full(4, 30.0)
    patches = np.stack([_patch(k) for k in ("line", "circle", "triangle", "line")])
    first = carry.carry(u, v, patches, 20.0)
    assert not first.carried.any()
    carry.remember(first, np.array([0, 1, 2, 0], np.uint8), np.full(4, 0.99, np.float32))
    # glyph 1 now looks like a line, glyph 2 moved 0.4 spacings, glyph 3 was unknown before
    now = patches.copy()
    now[1] = _patch("line")
    nxt = carry.carry(u + np.array([1.0, 0.0, 8.0, 0.5]), v, now, 20.0)
    assert nxt.carried.tolist() == [True, False, False, True]
    assert nxt.label[0] == 0 and nxt.label[1] == LABEL_UNKNOWN
    # a label below min_confidence is not carried either
    carry.remember(nxt, np.array([0, 0, 2, 0], np.uint8),
                   np.array([0.99, 0.99, 0.99, 0.5], np.float32))
    third = carry.carry(u + np.array([1.0, 0.0, 8.0, 0.5]), v, now, 20.0)
    assert third.carried.tolist() == [True, True, True, False]


def test_every_glyph_is_classified_again_within_refresh_frames():
    refresh = 4
    carry = LabelCarry(CarryParams(refresh_frames=refresh))
    n = 40
    u = np.tile(np.arange(8) * 20.0, 5)
    v = np.repeat(np.arange(5) * 20.0, 8)
    patches = np.stack([_patch(("line", "circle", "triangle")[i % 3]) for i in range(n)])
    label = (np.arange(n) % 3).astype(np.uint8)
    classified = []
    for _ in range(3 * refresh):
        frame = carry.carry(u, v, patches, 20.0)
        classified.append(~frame.carried)
        carry.remember(frame, label, np.full(n, 0.99, np.float32))
    seen = np.asarray(classified)
    for start in range(1, len(seen) - refresh + 1):   # any refresh consecutive frames
        assert seen[start:start + refresh].any(axis=0).all()
    # spread out: no frame after the first classifies more than about 1 / refresh of them
    assert seen[1:].sum(axis=1).max() <= n // refresh + 1


def test_carry_off_classifies_everything(frames):
    off, _ = _pipelines()
    off.process(*frames[0])
    assert off.process(*frames[0]).carried == 0
    off.close()


@pytest.mark.parametrize("bad", [dict(radius=0.0), dict(radius=0.6), dict(min_correlation=1.5),
                                 dict(min_confidence=-0.1), dict(refresh_frames=0)])
def test_carry_params_out_of_range_are_refused(bad):
    with pytest.raises(ValueError):
        CarryParams(**bad).validate()


def _lattice(rows=8, cols=10, r0=5, c0=7, spacing=16.0):
    """A perfect lattice of glyphs showing the shipped pattern's cells r0.., c0.. ."""
    from tactile_sl_decoder.decode.grid import build_grid

    pattern = PatternSpec.load().array
    rr, cc = np.mgrid[0:rows, 0:cols]
    u = 40.0 + spacing * cc.ravel()
    v = 30.0 + spacing * rr.ravel()
    grid = build_grid(u, v)
    cell = (rr.ravel() + r0) * pattern.shape[1] + cc.ravel() + c0
    label = pattern[rr.ravel() + r0, cc.ravel() + c0].astype(np.uint8)
    return grid, cell, label, np.full(len(cell), 0.99, np.float32), pattern


def test_carried_cells_are_confirmed_only_where_label_and_neighbours_agree():
    from tactile_sl_decoder.decode.codewords import Codebook, CodewordDecoder, DecodeParams

    grid, cell, label, conf, pattern = _lattice()
    codebook = Codebook(pattern, (3, 3), 3, 3)
    decoders = {m: CodewordDecoder(codebook, DecodeParams(mirrored=m)) for m in (False, True)}

    def verify_carried_cells(nbr, cell, label, conf, pattern, mirrored=False):
        assert nbr is grid.nbr
        return decoders[mirrored].confirm(grid, cell, label, conf)
    assert verify_carried_cells(grid.nbr, cell, label, conf, pattern).all()
    # every cell one column off (a jump by one spacing): the labels give it away
    ok = verify_carried_cells(grid.nbr, cell + 1, label, conf, pattern)
    assert ok.mean() < 0.5
    # one glyph with a wrong cell: it fails, and so do its neighbours (they disagree)
    bad = cell.copy()
    i = 3 * 10 + 4
    bad[i] = cell[i] + 2 * pattern.shape[1] + 3
    label_bad = label.copy()
    label_bad[i] = pattern.ravel()[bad[i]]             # even with a label that fits it
    ok = verify_carried_cells(grid.nbr, bad, label_bad, conf, pattern)
    assert not ok[i] and not ok[i + 1] and not ok[i - 10]
    # a cell carried to two glyphs; an unknown label; mirrored artwork reverses columns
    dup = cell.copy()
    dup[0] = dup[1]
    assert not verify_carried_cells(grid.nbr, dup, label, conf, pattern)[[0, 1]].any()
    unknown = label.copy()
    unknown[5] = LABEL_UNKNOWN
    assert not verify_carried_cells(grid.nbr, cell, unknown, conf, pattern)[5]
    assert not verify_carried_cells(grid.nbr, cell, label, conf, pattern, mirrored=True).any()


def test_carried_cells_come_from_the_matched_previous_glyph():
    from tactile_sl_decoder.decode.track import carried_cells

    prev_row = np.array([2, -1, 4], np.int32)
    prev_col = np.array([3, -1, 5], np.int32)
    out = carried_cells(np.array([2, -1, 0, 1]), prev_row, prev_col, cols=10)
    assert out.tolist() == [45, -1, 23, -1]


def test_a_pipeline_refuses_carry_settings_out_of_range():
    params = PipelineParams(threads=1)
    params.carry.refresh_frames = 0
    with pytest.raises(ValueError, match="refresh_frames"):
        StereoPipeline(PatternSpec.load(), params=params)


def test_normalised_patches_and_correlations_give_the_numpy_bits(frames):
    """The kernels behind normalised_patches and the correlation are numpy's code bit for
    bit: real glyph patches of a bag, random, flat and bright ones, other patch sizes."""
    from tactile_sl_decoder.classify import carry as carry_module
    from tactile_sl_decoder.extract.extraction import extract_symbols

    assert carry_module._kernels_are_exact()
    rng = np.random.default_rng(5)
    real = np.concatenate([extract_symbols(g).patches for f in frames[:6] for g in f[:2]])
    assert len(real) > 500
    real.flags.writeable = False                     # a bag's patches may be read-only
    cases = [real, rng.integers(0, 256, (200, PATCH_SIZE, PATCH_SIZE), dtype=np.uint8),
             rng.integers(230, 256, (50, PATCH_SIZE, PATCH_SIZE), dtype=np.uint8),
             np.full((3, PATCH_SIZE, PATCH_SIZE), 128, np.uint8),
             rng.integers(0, 256, (30, 13, 13), dtype=np.uint8),
             rng.integers(0, 256, (30, 7, 9), dtype=np.uint8)]
    for patches in cases:
        want = carry_module.numpy_normalised_patches(patches)
        got = carry_module.normalised_patches(patches)
        assert got.dtype == np.float32 and np.array_equal(got, want), patches.shape
        ia = rng.integers(0, len(want), 400)
        ib = np.clip(ia + rng.integers(-2, 3, 400), 0, len(want) - 1)
        assert np.array_equal(carry_module.correlations(want, ia, want, ib),
                              np.einsum("ij,ij->i", want[ia], want[ib]))
    empty = np.zeros(0, np.int64)
    assert carry_module.correlations(want, empty, want, empty).shape == (0,)


def test_normalised_patches_fall_back_to_numpy_where_the_kernels_are_not_exact(monkeypatch):
    """A failed self-check: numpy's code runs (same results), not the kernels."""
    from tactile_sl_decoder.classify import carry as carry_module

    def refuse(*args):
        raise AssertionError("kernel called")

    patches = np.random.default_rng(3).integers(0, 256, (20, PATCH_SIZE, PATCH_SIZE),
                                                dtype=np.uint8)
    want = carry_module.numpy_normalised_patches(patches)
    monkeypatch.setattr(carry_module, "_kernels_are_exact", lambda: False)
    monkeypatch.setattr(carry_module, "_normalised", refuse)
    monkeypatch.setattr(carry_module, "_row_dots", refuse)
    assert np.array_equal(carry_module.normalised_patches(patches), want)
    idx = np.arange(20)
    assert np.array_equal(carry_module.correlations(want, idx, want, idx[::-1]),
                          np.einsum("ij,ij->i", want, want[::-1]))
    carry = LabelCarry()
    first = carry.carry(np.arange(20.0) * 20, np.full(20, 30.0), patches, 20.0)
    carry.remember(first, np.zeros(20, np.uint8), np.ones(20, np.float32))
    assert carry.carry(np.arange(20.0) * 20, np.full(20, 30.0), patches, 20.0).carried.any()


def test_the_carry_self_check_sees_a_wrong_kernel(monkeypatch):
    """_kernels_are_exact compares bits: a normalisation off by one ulp fails it."""
    from tactile_sl_decoder.classify import carry as carry_module

    kernel = carry_module._normalised

    def off(patches, crop):
        out = kernel(patches, crop)
        out[-1, 0] = np.nextafter(out[-1, 0], np.float32(np.inf))
        return out

    check = carry_module._kernels_are_exact.__wrapped__
    assert check()
    monkeypatch.setattr(carry_module, "_normalised", off)
    assert not check()
