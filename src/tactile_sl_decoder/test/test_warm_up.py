"""The rendered warm-up frame runs the whole pipeline and leaves nothing behind."""
import pytest

from tactile_sl_common.images import to_gray
from tactile_sl_decoder.frames import bag_frames
from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline
from tactile_sl_decoder.warm_up import pattern_pair, warm_up

from ros_harness import BAGS


@pytest.mark.parametrize("mirrored", [False, True])
def test_the_rendered_pair_decodes_nearly_every_cell(mirrored):
    pattern = PatternSpec.load(None)
    pipe = StereoPipeline(pattern, None, PipelineParams(threads=1))
    pipe.params.decode.mirrored = mirrored
    try:
        visible = pattern.array.size
        assert warm_up(pipe) > 0.8 * visible        # extraction to stereo all ran
        left, right, rig = pattern_pair(pattern.array, pattern.symbols, pattern.pitch_m,
                                        mirrored)
        result = pipe.process(left, right, rig, rig)
        assert result.carried == 0                  # the warm-up frame was forgotten
        z = result.points["z"]
        # the pad at the depth where its pitch spans 17 px: f * pitch / 17 px
        assert abs(float(z.mean()) - 600.0 * pattern.pitch_m / 17.0) < 1e-4
    finally:
        pipe.close()


def test_frames_after_the_warm_up_are_the_bytes_of_a_fresh_pipeline():
    frames = [(to_gray(f.left_image), to_gray(f.right_image), f.left_info, f.right_info)
              for f in list(bag_frames(BAGS / "two_contacts.mcap"))[:3]]
    pattern = PatternSpec.load(None)
    fresh = StereoPipeline(pattern, None, PipelineParams(threads=1))
    warmed = StereoPipeline(pattern, None, PipelineParams(threads=1))
    try:
        warm_up(warmed)
        for frame in frames:             # the second and third carry labels and cells
            a, b = fresh.process(*frame), warmed.process(*frame)
            assert a.points.tobytes() == b.points.tobytes()
            assert (a.carried, a.tracked) == (b.carried, b.tracked)
    finally:
        fresh.close()
        warmed.close()


def test_an_alphabet_without_default_glyphs_is_a_clear_error():
    """What the node catches (and logs): it then subscribes without the warm-up frame."""
    import numpy as np

    with pytest.raises(ValueError, match="no default glyph set"):
        pattern_pair(np.zeros((6, 6), np.uint8), symbols=40)
