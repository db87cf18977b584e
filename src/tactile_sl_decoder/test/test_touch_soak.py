"""The live touch checks of tools/soak_touch.py and tests/test_touch_live.py."""
from tactile_sl_common.bag_io import BagReader
from tactile_sl_decoder.frames import bag_frames
from tactile_sl_decoder.tooling.touch_soak import (
    ContactCheck,
    Thresholds,
    tare_expected,
    write_phase_bag,
)

from ros_harness import BAGS


def test_hysteresis_against_the_thresholds_in_force():
    check = ContactCheck(Thresholds(0.010, 0.005))
    assert check.check(100, 150, False, 0.008)          # below on: stays off
    assert check.check(200, 250, True, 0.020)           # above on
    assert check.check(300, 350, True, 0.007)           # between: held
    assert check.held == 1
    assert not check.check(400, 450, True, 0.004)       # below off must be off
    assert check.violations and "4.0 mN" in check.violations[0]
    check.change(Thresholds(1.0, 0.3), requested_ns=500, answered_ns=600)
    assert check.in_force(450, 490) == [Thresholds(0.010, 0.005)]   # arrived before: old
    assert len(check.in_force(550, 650)) == 2                       # in flight: either
    assert check.in_force(700, 750) == [Thresholds(1.0, 0.3)]        # stamped after: new
    assert check.check(550, 650, True, 0.5)             # old thresholds still possible
    assert not check.check(700, 750, True, 0.2)         # new ones: below off
    check.reset()
    assert check.check(800, 850, False, 0.5) and check.check(900, 950, False, 0.5)


def test_tare_rule():
    assert tare_expected(False, 5e-6, 5e-5)
    assert not tare_expected(True, 5e-6, 5e-5) and not tare_expected(False, 2e-4, 5e-5)


def test_phase_bag_alternates_and_restamps(tmp_path):
    out = tmp_path / "phases.mcap"
    assert write_phase_bag(BAGS / "touch_halfspace.mcap", out, [0], [2, 3], 3, 2) == 5
    source = list(bag_frames(BAGS / "touch_halfspace.mcap", ground_truth=False))
    frames = list(bag_frames(out, ground_truth=False))
    assert [f.stamp_ns - frames[0].stamp_ns for f in frames] == [0, 10**8, 2 * 10**8,
                                                                  3 * 10**8, 4 * 10**8]
    assert [bytes(f.left_image.data) for f in frames] == [
        bytes(source[i].left_image.data) for i in (0, 0, 0, 2, 3)]
    assert not any("ground_truth" in t for t in BagReader(out).topics)
