"""`tactile-sl replay` writes /tactile/slip for the bundled slip bags, stamped like their frames,
and what it writes agrees with the bags' ground_truth/slip (issue 24's acceptance on them)."""
import math

import pytest

from tactile_sl_common.bag_io import BagReader
from tactile_sl_decoder.cli import main as cli_main
from tactile_sl_decoder.contract import SLIP_GROSS, SLIP_PARTIAL, SLIP_STICK

from ros_harness import BAGS

pytestmark = pytest.mark.slow


def _slips(path, topic):
    reader = BagReader(path)
    return {m.header.stamp.sec * 10**9 + m.header.stamp.nanosec: (raw.log_time_ns, m)
            for raw, m in reader.messages([topic])}


@pytest.mark.parametrize("bag", ["slip_halfspace", "slip_two_contacts"])
def test_replay_writes_slip_like_the_ground_truth(tmp_path, bag):
    out = tmp_path / "out.mcap"
    source = BAGS / f"{bag}.mcap"
    assert cli_main(["replay", str(source), "-o", str(out), "--no-progress"]) == 0
    written = _slips(out, "/tactile/slip")
    truth = _slips(source, "/tactile/ground_truth/slip")
    images = _slips(source, "/tactile/left/image_raw")
    # one per frame after the (first) reference frame, stamped exactly like it
    assert sorted(written) == sorted(images)[1:]
    for stamp, (log_time, msg) in written.items():
        assert log_time == stamp and msg.header.frame_id == "tactile_pad"
        true = truth[stamp][1]
        if true.slip_margin <= 0.6:          # a thinner slip annulus may still read stick
            assert msg.state == true.state, (stamp, msg.state, true.state)
        else:
            assert msg.state in (SLIP_STICK, SLIP_PARTIAL), (stamp, msg.state)
        assert abs(msg.slip_margin - true.slip_margin) < 0.1
        if true.state == SLIP_PARTIAL:
            assert abs(msg.stick_ratio - true.stick_ratio) < 0.1
        if true.slip_margin <= 0.5 and true.state in (SLIP_PARTIAL, SLIP_GROSS):
            assert msg.friction_coefficient == pytest.approx(true.friction_coefficient,
                                                             rel=0.1)
        assert math.isnan(msg.friction_coefficient) == (msg.state == SLIP_STICK)
        assert math.hypot(msg.direction.x - true.direction.x,
                          msg.direction.y - true.direction.y) < 0.05
