"""`tactile-sl view`'s bag source: a camera-only bag decoded here equals `tactile-sl replay`;
a bag with recorded outputs is shown as recorded; frames are shown by index, any order."""
import pytest

from tactile_sl_common.bag_io import BagReader, BagWriter
from tactile_sl_viewer.bag_source import BagSource

from ros_harness import BAGS

pytestmark = pytest.mark.slow

BAG = BAGS / "touch_halfspace.mcap"


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    """`tactile-sl replay` of the bag: its touch and point outputs, raw, by topic."""
    from tactile_sl_decoder.cli import main as cli_main

    out = tmp_path_factory.mktemp("replay") / "out.mcap"
    assert cli_main(["replay", str(BAG), "-o", str(out), "--no-progress"]) == 0
    return out


def _wrenches(source):
    found = {}
    for i, stamp in enumerate(source.stamps):
        source.seek(i)
        frame = source.assembler.latest()
        assert frame is not None and frame.stamp_ns == stamp
        assert "image" in frame.parts
        if "wrench" in frame.parts:
            f = frame.parts["wrench"].wrench.force
            found[stamp] = (f.x, f.y, f.z)
    return found


def _replay_wrenches(path):
    out = {}
    for raw, msg in BagReader(path).messages(["/tactile/wrench"]):
        f = msg.wrench.force
        out[raw.log_time_ns] = (f.x, f.y, f.z)
    return out


def test_a_camera_bag_is_decoded_as_tactile_sl_replay_decodes_it(replayed):
    seen = []
    source = BagSource(BAG, progress=lambda done, total: seen.append((done, total)))
    assert source.decoded_here and len(source.stamps) == 5
    assert seen[-1] == (5, 5)
    assert _wrenches(source) == _replay_wrenches(replayed)     # the reference frame has none
    source.seek(99)                                            # clamped
    assert source.index == 4 and source.extra()["bag"]["count"] == 5
    source.seek(2)
    frame = source.assembler.latest()
    assert {"glyphs", "points", "field", "contact", "depth"} <= set(frame.parts)


def test_a_bag_with_recorded_outputs_is_shown_as_recorded(replayed, tmp_path):
    recorded = tmp_path / "recorded.mcap"
    with BagWriter(recorded) as writer:
        for path in (BAG, replayed):
            for raw in BagReader(path).raw_messages():
                writer.write_raw(raw.topic, raw.schema_name, raw.data, raw.log_time_ns)
    source = BagSource(recorded)
    assert not source.decoded_here
    assert _wrenches(source) == _replay_wrenches(replayed)
    with pytest.raises(ValueError, match="decode"):
        BagSource(recorded, decode="sometimes")
