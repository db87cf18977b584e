"""Replay selection, naming, pacing and restamping rules (no ROS graph needed)."""
import numpy as np
import pytest

from tactile_sl_camera.replay import ReplayPlan, Restamper, relative_name
from tactile_sl_common.bag_io import BagError, BagWriter, header_stamp_of_cdr
from tactile_sl_common.images import image_fields


@pytest.fixture
def bag(tmp_path):
    path = tmp_path / "b.mcap"
    with BagWriter(path) as writer:
        for i in range(3):
            stamp = {"sec": 50, "nanosec": i * 100_000_000}
            t_ns = 50 * 10**9 + i * 100_000_000
            for side in ("left", "right"):
                writer.write(f"/tactile/{side}/image_raw", "sensor_msgs/msg/Image",
                             {"header": {"stamp": stamp, "frame_id": side},
                              **image_fields(np.zeros((2, 2), np.uint8))}, t_ns)
            writer.write("/tactile/ground_truth/points", "std_msgs/msg/String",
                         {"data": "not replayed by default"}, t_ns)
    return path


def test_relative_names():
    assert relative_name("/tactile/left/image_raw", "/tactile") == "left/image_raw"
    assert relative_name("/tactile/left/image_raw", "tactile/") == "left/image_raw"
    assert relative_name("/other/left/image_raw", "/tactile") == "other/left/image_raw"
    assert relative_name("/left/image_raw", "") == "left/image_raw"


def test_default_selection_is_images_and_camera_info(bag):
    plan = ReplayPlan(bag)
    assert sorted(plan.outputs.values()) == ["left/image_raw", "right/image_raw"]
    assert plan.message_count == 6


def test_rate_scales_the_schedule(bag):
    due = [item.due_s for item in ReplayPlan(bag, rate=2.0).items()]
    assert due == pytest.approx([0, 0, 0.05, 0.05, 0.1, 0.1])
    assert all(item.due_s == 0 for item in ReplayPlan(bag, rate=0).items())


def test_restamper_stamps_each_frame_when_it_goes_out(bag):
    clock = iter([7_000_000_000, 7_033_000_000, 7_066_000_000])
    restamp = Restamper(lambda: next(clock))
    out = [restamp(item) for item in ReplayPlan(bag, rate=3.0).items()]
    stamps = [header_stamp_of_cdr(data) for data, _ in out]
    # left and right of a frame share the new stamp; one clock reading per frame
    assert stamps == [(7, 0), (7, 0), (7, 33_000_000), (7, 33_000_000),
                      (7, 66_000_000), (7, 66_000_000)]
    assert [ns for _, ns in out][::2] == [7_000_000_000, 7_033_000_000, 7_066_000_000]


def test_requested_topic_must_exist(bag):
    with pytest.raises(BagError, match="missing topic"):
        ReplayPlan(bag, topics=["left/camera_info"])
    assert ReplayPlan(bag, topics=["left/image_raw"]).message_count == 3


def test_bag_without_camera_topics_is_an_error(tmp_path):
    path = tmp_path / "c.mcap"
    with BagWriter(path) as writer:
        writer.write("/chatter", "std_msgs/msg/String", {"data": "hi"}, 1)
    with pytest.raises(BagError, match="no sensor_msgs/Image or CameraInfo topics"):
        ReplayPlan(path)
    with pytest.raises(ValueError, match="rate must be >= 0"):
        ReplayPlan(path, topics=["/chatter"], rate=-1)


def test_a_loop_starts_the_next_pass_one_frame_period_after_the_last(bag):
    """Issue 28, item 13: the next pass started at once, so a looping 10 Hz bag of 7 frames
    played at 11.7 Hz (and of 4 frames at 13.3 Hz): one frame period missing at each wrap."""
    plan = ReplayPlan(bag, rate=1.0)
    assert plan.next_pass_start(10.0, 10.2) == 10.2          # nothing measured yet
    list(plan.items())                                         # three frames, 0.1 s apart
    assert plan.span_ns == 200_000_000 and plan.frame_period_ns == 100_000_000
    assert plan.next_pass_start(10.0, 10.2) == pytest.approx(10.3)   # on schedule
    assert plan.next_pass_start(10.0, 11.0) == pytest.approx(11.1)   # behind: a period on
    half = ReplayPlan(bag, rate=2.0)
    list(half.items())
    assert half.next_pass_start(10.0, 10.1) == pytest.approx(10.15)
    fast = ReplayPlan(bag, rate=0)
    list(fast.items())
    assert fast.next_pass_start(10.0, 10.01) == 10.01


def test_a_bag_of_one_frame_loops_at_10_hz(tmp_path):
    path = tmp_path / "one.mcap"
    with BagWriter(path) as writer:
        writer.write("/tactile/left/image_raw", "sensor_msgs/msg/Image",
                     {"header": {"stamp": {"sec": 5, "nanosec": 0}, "frame_id": "left"},
                      **image_fields(np.zeros((2, 2), np.uint8))}, 5 * 10**9)
    plan = ReplayPlan(path, rate=2.0)
    list(plan.items())
    assert plan.span_ns == 0 and plan.frame_period_ns == 100_000_000
    assert plan.next_pass_start(10.0, 10.001) == pytest.approx(10.051)   # not a busy loop
