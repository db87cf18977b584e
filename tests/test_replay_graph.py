"""The replay node, run as `ros2 run` would run it, delivers a bag's frames intact over DDS."""
from __future__ import annotations

import pathlib
import time

import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image

from tactile_sl_common.bag_io import BagReader, BagWriter
from tactile_sl_common.images import image_fields

from ros_harness import Probe, start_node, stop, wait_until

pytestmark = pytest.mark.ros


def write_test_bag(path: pathlib.Path, frames: int = 6) -> None:
    """Random images (so any corruption shows), left and right stamped identically."""
    rng = np.random.default_rng(7)
    with BagWriter(path) as bag:
        for i in range(frames):
            stamp = {"sec": 1_700_000_000 + i, "nanosec": 987_654_321 - i}
            t_ns = stamp["sec"] * 10**9 + stamp["nanosec"]
            for side in ("left", "right"):
                header = {"stamp": stamp, "frame_id": f"tactile_{side}_optical_frame"}
                pixels = rng.integers(0, 256, (48, 64), dtype=np.uint8)
                bag.write(f"/tactile/{side}/image_raw", "sensor_msgs/msg/Image",
                          {"header": header, **image_fields(pixels)}, t_ns)
                bag.write(f"/tactile/{side}/camera_info", "sensor_msgs/msg/CameraInfo",
                          {"header": header, "height": 48, "width": 64,
                           "distortion_model": "plumb_bob", "d": [0.0] * 5,
                           "k": [60.0, 0, 32, 0, 60.0, 24, 0, 0, 1],
                           "r": [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
                           "p": [60.0, 0, 32, 0, 0, 60.0, 24, 0, 0, 0, 1, 0]}, t_ns)


def collect_replay(bag: pathlib.Path, domain_id: int, tmp_path: pathlib.Path,
                   extra_args: list[str] = ()) -> tuple[dict, int]:
    """Run `replay` on the bag and return {topic: [(stamp_ns, data bytes)]} and its exit code."""
    received: dict[str, list] = {}
    probe = Probe("test_listener", domain_id, namespace="/tactile")
    node, executor = probe.node, probe.executor
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    try:
        for side in ("left", "right"):
            for suffix, kind in (("image_raw", Image), ("camera_info", CameraInfo)):
                topic = f"{side}/{suffix}"
                received[topic] = []

                def keep(msg, topic=topic):
                    stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
                    data = bytes(msg.data) if hasattr(msg, "data") else None
                    received[topic].append((stamp, data))

                node.create_subscription(kind, topic, keep, qos)
        process = start_node("tactile_sl_camera", "replay", domain_id, [
            "-r", "__ns:=/tactile", "-p", f"bag:={bag}", "-p", "rate:=10.0",
            "-p", "reliability:=reliable", "-p", "depth:=100",
            "-p", "wait_for_subscribers:=1", *extra_args], tmp_path / "replay.log")
        wait_until(lambda: process.poll() is not None, 30.0,
                   lambda: executor.spin_once(timeout_sec=0.05))
        for _ in range(20):  # drain what is still in flight
            executor.spin_once(timeout_sec=0.05)
        code = stop(process)
        return received, code
    finally:
        probe.close()


def bag_images(path: pathlib.Path) -> dict[str, list]:
    reader = BagReader(path)
    out: dict[str, list] = {}
    for raw, msg in reader.messages(reader.topics_of_type("sensor_msgs/msg/Image")):
        topic = raw.topic.removeprefix("/tactile/")
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        out.setdefault(topic, []).append((stamp, bytes(msg.data)))
    return out


def test_images_arrive_with_stamps_and_bytes_intact(tmp_path, domain_id):
    bag = tmp_path / "frames.mcap"
    write_test_bag(bag)
    received, code = collect_replay(bag, domain_id, tmp_path)
    assert code == 0, (tmp_path / "replay.log").read_text()
    expected = bag_images(bag)
    for topic, frames in expected.items():
        assert received[topic] == frames, f"{topic}: frames differ from the bag"
    left = [s for s, _ in received["left/camera_info"]]
    right = [s for s, _ in received["right/camera_info"]]
    assert left == right == [s for s, _ in expected["left/image_raw"]]


def test_bundled_bag_replays_intact(tmp_path, domain_id, repo):
    bags = sorted((repo / "bags").glob("*.mcap"), key=lambda p: p.stat().st_size)
    assert bags, "no bundled bags in bags/ (run `make bags`)"
    received, code = collect_replay(bags[0], domain_id, tmp_path)
    assert code == 0, (tmp_path / "replay.log").read_text()
    expected = bag_images(bags[0])
    assert expected, f"{bags[0]} carries no images"
    for topic, frames in expected.items():
        assert received[topic] == frames, f"{bags[0].name} {topic}: frames differ"


def test_restamp_keeps_stereo_pairs_identical(tmp_path, domain_id):
    bag = tmp_path / "frames.mcap"
    write_test_bag(bag, frames=4)
    received, code = collect_replay(bag, domain_id, tmp_path, ["-p", "restamp:=true"])
    assert code == 0
    left = [s for s, _ in received["left/image_raw"]]
    right = [s for s, _ in received["right/image_raw"]]
    assert left == right and len(left) == 4
    # stamped when published (now), increasing, about 1/rate apart (recorded: 1 s apart)
    assert abs(left[0] / 1e9 - time.time()) < 60
    gaps = np.diff(left) / 1e9
    assert (gaps > 0).all() and (gaps < 0.5).all(), gaps
    # pixels unchanged by restamping
    assert [d for _, d in received["left/image_raw"]] == [
        d for _, d in bag_images(bag)["left/image_raw"]]


@pytest.mark.parametrize("damage, expected", [
    ("truncate", "truncated"), ("garbage", "not an MCAP file"), ("missing", "no such bag")])
def test_bad_bag_is_a_clear_error(tmp_path, domain_id, damage, expected):
    bag = tmp_path / "bad.mcap"
    if damage != "missing":
        write_test_bag(bag, frames=2)
        data = bag.read_bytes()
        bag.write_bytes(data[: len(data) // 2] if damage == "truncate" else b"not a bag" + data)
    process = start_node("tactile_sl_camera", "replay", domain_id,
                         ["-p", f"bag:={bag}"], tmp_path / "replay.log")
    code = process.wait(30)
    log = (tmp_path / "replay.log").read_text()
    assert code != 0
    assert expected in log and str(bag) in log, log
    assert "Traceback" not in log, log


def test_a_chunk_failing_its_crc_while_playing_ends_the_node_with_status_1(tmp_path, domain_id):
    """Issue 28, item 12: the node logged '[ERROR] ... fails its CRC check' and exited 0."""
    source, bag = tmp_path / "source.mcap", tmp_path / "crc.mcap"
    write_test_bag(source, frames=2)
    with BagWriter(bag, compression="none") as out:       # the pixels as they are
        for raw in BagReader(source).raw_messages():
            out.write_raw(raw.topic, raw.schema_name, raw.data, raw.log_time_ns)
    data = bytearray(bag.read_bytes())
    middle = len(data) // 3                 # inside an image's pixels: the chunk CRC fails
    data[middle:middle + 16] = bytes(16)
    bag.write_bytes(bytes(data))
    process = start_node("tactile_sl_camera", "replay", domain_id,
                         ["-p", f"bag:={bag}"], tmp_path / "replay.log")
    code = process.wait(30)
    log = (tmp_path / "replay.log").read_text()
    assert code == 1 and "CRC" in log and "FATAL" in log, log
    assert "Traceback" not in log and "finished:" not in log, log
