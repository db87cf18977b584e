"""Looping replay and launch files (issue 12, finding 6).

A looping replay without ``restamp`` repeated the recorded stamps on every pass, so the
decoder dropped every later pass as stale: loop now implies restamp and stamps keep moving
forward.  Launch files (only syntax-checked here: launch_ros is not installed) describe every
argument, pass ``restamp`` and read ``stages`` as a ROS boolean.
"""
from __future__ import annotations

import ast
import time

import pytest

from ros_harness import REPO, next_domain_id, start_node, stop

LAUNCH_FILES = sorted(REPO.glob("src/*/launch/*.launch.py"))


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_every_launch_argument_has_a_description(path):
    tree = ast.parse(path.read_text())
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)
             and getattr(n.func, "id", "") == "DeclareLaunchArgument"]
    assert calls
    for call in calls:
        assert any(k.arg == "description" for k in call.keywords), \
            f"{path.name}:{call.lineno}: DeclareLaunchArgument without a description"


def test_sensor_launch_passes_restamp_and_reads_stages_as_a_boolean():
    text = (REPO / "src/tactile_sl_decoder/launch/tactile_sl.launch.py").read_text()
    assert '"restamp": LaunchConfiguration("restamp")' in text
    assert "== 'true'" not in text and ".lower() in ('true', '1')" in text


@pytest.mark.ros
def test_looping_replay_keeps_stamps_moving_forward(tmp_path):
    rclpy = pytest.importorskip("rclpy")
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    from tactile_sl_camera.bag_io import BagReader, BagWriter

    bag = tmp_path / "two.mcap"
    stamps: list[int] = []
    with BagWriter(bag) as out:
        for raw in BagReader(REPO / "bags" / "edge.mcap").raw_messages():
            if raw.log_time_ns not in stamps:
                if len(stamps) == 2:
                    break
                stamps.append(raw.log_time_ns)
            out.write_raw(raw.topic, raw.schema_name, raw.data, raw.log_time_ns)
    domain = next_domain_id()
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("loop_listener", namespace="/tactile", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
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
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    log = (tmp_path / "replay.log").read_text()
    assert len(got) >= 5, log
    assert all(b > a for a, b in zip(got, got[1:])), f"stamps not increasing: {got}"
    assert "loop implies restamp" in log
