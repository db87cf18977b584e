"""Looping replay (issue 12, finding 6).

A looping replay without ``restamp`` repeated the recorded stamps on every pass, so the
decoder dropped every later pass as stale: loop now implies restamp and stamps keep moving
forward.  (The launch files' side of the finding: ``test_launch_files.py``.)
"""
from __future__ import annotations

import time

import pytest

from ros_harness import BAGS, Probe, next_domain_id, start_node, stop

pytestmark = pytest.mark.ros


def test_looping_replay_keeps_stamps_moving_forward(tmp_path):
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    from tactile_sl_common.bag_io import BagReader, BagWriter

    bag = tmp_path / "two.mcap"
    stamps: list[int] = []
    with BagWriter(bag) as out:
        for raw in BagReader(BAGS / "edge.mcap").raw_messages():
            if raw.log_time_ns not in stamps:
                if len(stamps) == 2:
                    break
                stamps.append(raw.log_time_ns)
            out.write_raw(raw.topic, raw.schema_name, raw.data, raw.log_time_ns)
    domain = next_domain_id()
    probe = Probe("loop_listener", domain, namespace="/tactile")
    node, executor = probe.node, probe.executor
    got: list[int] = []
    node.create_subscription(Image, "left/image_raw", lambda m: got.append(
        m.header.stamp.sec * 10**9 + m.header.stamp.nanosec), qos_profile_sensor_data)
    proc = start_node("tactile_sl_camera", "replay", domain, [
        "-r", "__ns:=/tactile", "-p", f"bag:={bag}", "-p", "loop:=true", "-p", "loops:=3",
        "-p", "rate:=1.0", "-p", "wait_for_subscribers:=1"], tmp_path / "replay.log")
    try:
        deadline = time.monotonic() + 40
        while len(got) < 6 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
    finally:
        assert stop(proc) == 0
        probe.close()
    log = (tmp_path / "replay.log").read_text()
    assert len(got) >= 5, log
    assert all(b > a for a, b in zip(got, got[1:])), f"stamps not increasing: {got}"
    assert "loop implies restamp" in log


def test_a_loop_keeps_the_recorded_frame_rate_across_the_wrap(tmp_path):
    """Issue 28, item 13: a looping 10 Hz bag played at 11.7 Hz (7 frames) and 13.3 Hz
    (4 frames): the next pass started at once, one frame period missing at each wrap."""
    import numpy as np
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    from tactile_sl_common.bag_io import BagWriter
    from tactile_sl_common.images import image_fields

    bag = tmp_path / "four.mcap"
    with BagWriter(bag) as out:
        for i in range(4):                              # 10 Hz
            t = 1_700_000_000 * 10**9 + i * 100_000_000
            header = {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9}, "frame_id": "cam"}
            for side in ("left", "right"):
                out.write(f"/tactile/{side}/image_raw", "sensor_msgs/msg/Image",
                          {"header": header, **image_fields(np.zeros((8, 8), np.uint8))}, t)
    domain = next_domain_id()
    probe = Probe("wrap_listener", domain, namespace="/tactile")
    got: list[int] = []
    probe.node.create_subscription(Image, "left/image_raw", lambda m: got.append(
        m.header.stamp.sec * 10**9 + m.header.stamp.nanosec), qos_profile_sensor_data)
    proc = start_node("tactile_sl_camera", "replay", domain, [
        "-r", "__ns:=/tactile", "-p", f"bag:={bag}", "-p", "loop:=true", "-p", "loops:=5",
        "-p", "wait_for_subscribers:=1"], tmp_path / "replay.log")
    try:
        probe.spin_until(lambda: len(got) >= 20 or proc.poll() is not None, 40.0)
        probe.spin(0.3)
    finally:
        stop(proc)
        probe.close()
    log = (tmp_path / "replay.log").read_text()
    assert len(got) >= 16, log
    steps = np.diff(got) / 1e9
    rate = (len(got) - 1) / ((got[-1] - got[0]) / 1e9)
    assert 9.0 < rate < 11.0, (rate, steps)
    assert np.median(steps[3::4]) > 0.08, steps          # across each wrap: one period
