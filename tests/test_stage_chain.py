"""The stage nodes chained over DDS give the same points as the offline replay.

replay -> symbol_extractor (left, right) -> symbol_classifier (left, right)
       -> decoder (input:=symbols) -> points

Six installed executables, each its own process on one private domain (loopback only),
compared byte for byte with `tactile-sl replay` on the same bag.
"""
from __future__ import annotations

import time

import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

from tactile_sl_common.bag_io import BagReader
from tactile_sl_decoder.cli import main as tactile_sl

from ros_harness import Probe, start_node, stop

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_chained_stage_nodes_equal_offline_replay(tmp_path, domain_id, repo):
    bag = repo / "bags" / "sphere_deep_small.mcap"
    offline_bag = tmp_path / "offline.mcap"
    assert tactile_sl(["replay", str(bag), "-o", str(offline_bag), "--no-progress"]) == 0
    offline = {(m.header.stamp.sec, m.header.stamp.nanosec): bytes(m.data)
               for _, m in BagReader(offline_bag).messages(["/tactile/points"])}
    assert len(offline) == 7

    probe = Probe("chain_listener", domain_id, namespace="/tactile")
    node, executor = probe.node, probe.executor
    clouds: list[PointCloud2] = []
    node.create_subscription(PointCloud2, "points", clouds.append,
                             QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE))
    procs = []
    try:
        for side in ("left", "right"):
            # every hop reliable (the inputs default to best effort, as for camera drivers): a
            # best-effort subscriber that has not finished matching a new publisher on its side
            # drops what arrives, and this test needs every frame
            procs.append(start_node("tactile_sl_decoder", "symbol_extractor", domain_id,
                                    ["-r", f"__ns:=/tactile/{side}", "-r", "image:=image_raw",
                                     "-p", "qos.input.reliability:=reliable"],
                                    tmp_path / f"extractor_{side}.log"))
            procs.append(start_node("tactile_sl_decoder", "symbol_classifier", domain_id,
                                    ["-r", f"__ns:=/tactile/{side}"],
                                    tmp_path / f"classifier_{side}.log"))
        procs.append(start_node("tactile_sl_decoder", "decoder", domain_id, [
            "-r", "__ns:=/tactile", "-p", "input:=symbols", "-p", "qos.input.reliability:=reliable",
            "-r", "left/symbols:=left/labelled_symbols",
            "-r", "right/symbols:=right/labelled_symbols"], tmp_path / "decoder.log"))
        # Play only once every hop of the chain has its publisher and subscriber (messages
        # sent before two endpoints match are lost: volatile QoS).
        hops = [f"/tactile/{side}/{topic}" for side in ("left", "right")
                for topic in ("symbols", "labelled_symbols")]

        def connected() -> bool:
            return (node.count_publishers("/tactile/points") >= 1
                    and all(node.count_publishers(t) >= 1 and node.count_subscribers(t) >= 1
                            for t in hops))

        deadline = time.monotonic() + 60
        while not connected() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert connected(), "the stage nodes did not connect within 60 s"
        # let the remote endpoints match each other too: a volatile hop drops what is sent
        # before both ends matched (1 s lost the first frame once in a fresh CI run)
        settle = time.monotonic() + 3.0
        while time.monotonic() < settle:
            executor.spin_once(timeout_sec=0.05)
        # Paced by `points`, so no stage can be overrun; reliable so nothing is lost.
        replay = start_node("tactile_sl_camera", "replay", domain_id, [
            "-r", "__ns:=/tactile", "-p", f"bag:={bag}", "-p", "rate:=0.0",
            "-p", "reliability:=reliable", "-p", "wait_for_subscribers:=1",
            "-p", "wait_for_subscribers_timeout:=60.0", "-p", "wait_for_topic:=points",
            "-p", "wait_timeout:=15.0"], tmp_path / "replay.log")
        procs.append(replay)
        deadline = time.monotonic() + 120
        while replay.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        for _ in range(20):
            executor.spin_once(timeout_sec=0.05)
    finally:
        codes = [stop(p) for p in reversed(procs)]
        probe.close()
    assert codes[0] == 0, (tmp_path / "replay.log").read_text()
    online = {(c.header.stamp.sec, c.header.stamp.nanosec): bytes(c.data) for c in clouds}
    assert set(online) == set(offline), (tmp_path / "decoder.log").read_text()[-2000:]
    for stamp, data in offline.items():
        assert online[stamp] == data, f"frame {stamp}: chained points differ from offline"
