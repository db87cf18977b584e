"""Bag reading/writing: rosbag2 layout, clear errors for damaged bags, CDR restamping."""
import numpy as np
import pytest
from mcap.reader import make_reader

from tactile_sl_common.bag_io import (
    BagError,
    BagReader,
    BagWriter,
    header_stamp_of_cdr,
    message_definition,
    restamp_cdr,
)
from tactile_sl_common.images import ImageFormatError, image_fields, image_to_array, to_gray


def write_bag(path, frames=3):
    with BagWriter(path) as bag:
        for i in range(frames):
            pixels = np.full((4, 6, 3), i, dtype=np.uint8)
            bag.write("/tactile/left/image_raw", "sensor_msgs/msg/Image",
                      {"header": {"stamp": {"sec": 10, "nanosec": i}, "frame_id": "l"},
                       **image_fields(pixels, "bgr8")}, 10 * 10**9 + i)


def test_written_bag_has_rosbag2_layout(tmp_path):
    path = tmp_path / "a.mcap"
    write_bag(path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
    assert header.profile == "ros2"
    (schema,) = summary.schemas.values()
    (channel,) = summary.channels.values()
    assert schema.encoding == "ros2msg" and schema.name == "sensor_msgs/msg/Image"
    assert "MSG: std_msgs/Header" in schema.data.decode()
    assert channel.message_encoding == "cdr"
    assert "reliability" in channel.metadata["offered_qos_profiles"]


def test_round_trip_pixels_and_stamps(tmp_path):
    path = tmp_path / "a.mcap"
    write_bag(path)
    reader = BagReader(path)
    assert reader.topics["/tactile/left/image_raw"].message_count == 3
    got = [(m.header.stamp.nanosec, image_to_array(m)) for _, m in reader.messages()]
    assert [n for n, _ in got] == [0, 1, 2]
    assert all((pixels == n).all() and pixels.shape == (4, 6, 3) for n, pixels in got)


def test_definition_lists_each_dependency_once():
    text = message_definition("sensor_msgs/msg/CameraInfo")
    assert text.count("MSG: std_msgs/Header") == 1
    assert text.count("MSG: sensor_msgs/RegionOfInterest") == 1
    assert text.count("MSG: builtin_interfaces/Time") == 1


@pytest.mark.parametrize("damage, message", [
    (lambda b: b[: len(b) - 20], "truncated"),
    (lambda b: b"garbage!" + b[8:], "not an MCAP file"),
    (lambda b: b[:40] + b"\xff" * 200 + b[240:], "corrupt"),
])
def test_damaged_bags_name_the_file_and_problem(tmp_path, damage, message):
    path = tmp_path / "damaged.mcap"
    write_bag(path, frames=20)
    path.write_bytes(damage(path.read_bytes()))
    with pytest.raises(BagError) as err:
        reader = BagReader(path)
        list(reader.messages())
    assert str(path) in str(err.value) and message in str(err.value)


def test_missing_topics_are_listed(tmp_path):
    path = tmp_path / "a.mcap"
    write_bag(path)
    with pytest.raises(BagError, match="missing topic.*right/image_raw.*the bag has"):
        BagReader(path).require_topics(["/tactile/right/image_raw"])


def test_restamp_cdr_changes_only_the_stamp(tmp_path):
    path = tmp_path / "a.mcap"
    write_bag(path, frames=1)
    (raw,) = BagReader(path).raw_messages()
    changed = restamp_cdr(raw.data, 123, 456)
    assert header_stamp_of_cdr(changed) == (123, 456)
    assert changed[12:] == raw.data[12:]


def test_image_conversion_errors_are_specific():
    class Msg:
        height, width, step, encoding, data = 2, 3, 3, "mono8", bytes(6)

    assert to_gray(Msg()).shape == (2, 3)
    Msg.encoding = "yuv422"
    with pytest.raises(ImageFormatError, match="unsupported image encoding 'yuv422'"):
        image_to_array(Msg())
    Msg.encoding, Msg.data = "mono8", bytes(5)
    with pytest.raises(ImageFormatError, match="expected step\\*height = 6"):
        image_to_array(Msg())
    Msg.height = 0
    with pytest.raises(ImageFormatError, match="empty image"):
        image_to_array(Msg())


def test_no_temporary_file_outlives_an_interrupt_while_the_writer_is_made(tmp_path,
                                                                           monkeypatch):
    """SIGTERM right after the temporary file appeared once left it behind (a loaded CI)."""
    import gc
    import os
    import signal

    from tactile_sl_common import bag_io

    class Stopped(Exception):
        pass

    def stop(*_):
        raise Stopped

    started = bag_io.McapWriter.start
    gc.collect()     # no other test's writer left for a destructor to run the handler in

    def signalled_start(self, *args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)       # held back until the writer is whole
        return started(self, *args, **kwargs)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        monkeypatch.setattr(bag_io.McapWriter, "start", signalled_start)
        with pytest.raises(Stopped):
            bag_io.BagWriter(tmp_path / "out.mcap")
        assert list(tmp_path.iterdir()) == []
        monkeypatch.setattr(bag_io.McapWriter, "start", started)

        def interrupted_start(self, *args, **kwargs):
            raise KeyboardInterrupt

        monkeypatch.setattr(bag_io.McapWriter, "start", interrupted_start)
        with pytest.raises(KeyboardInterrupt):
            bag_io.BagWriter(tmp_path / "out.mcap")
        assert list(tmp_path.iterdir()) == []
    finally:
        signal.signal(signal.SIGTERM, previous)
    monkeypatch.setattr(bag_io.McapWriter, "start", started)
    # made, then dropped before its `with` block: its file goes with it
    writer = bag_io.BagWriter(tmp_path / "out.mcap")
    assert len(list(tmp_path.iterdir())) == 1
    del writer
    gc.collect()
    assert list(tmp_path.iterdir()) == []
