"""A SymbolArray crosses a process boundary over DDS with every field intact."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from tactile_sl_msgs.msg import SymbolArray

from ros_harness import Probe, ros_env, stop, wait_until

pytestmark = pytest.mark.ros

PUBLISHER = textwrap.dedent("""
    import sys, time
    import numpy as np
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from tactile_sl_msgs.msg import SymbolArray

    rclpy.init()
    node = rclpy.create_node("symbol_publisher")
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    pub = node.create_publisher(SymbolArray, "symbols", qos)
    rng = np.random.default_rng(3)
    n = 1000
    msg = SymbolArray()
    msg.header.stamp.sec = 1_700_000_123
    msg.header.stamp.nanosec = 999_999_999
    msg.header.frame_id = "tactile_left_optical_frame"
    msg.image_width, msg.image_height, msg.spacing_px = 640, 480, 17.25
    msg.u = rng.uniform(0, 640, n).astype(np.float32)
    msg.v = rng.uniform(0, 480, n).astype(np.float32)
    msg.area = rng.uniform(20, 90, n).astype(np.float32)
    label = rng.integers(0, 3, n).astype(np.uint8)
    label[::7] = SymbolArray.LABEL_UNKNOWN
    msg.label = label
    msg.confidence = rng.uniform(0, 1, n).astype(np.float32)
    msg.row = rng.integers(-1, 30, n).astype(np.int32)
    msg.col = rng.integers(-1, 30, n).astype(np.int32)
    msg.patch_size = 18
    msg.patches = rng.integers(0, 256, n * 18 * 18).astype(np.uint8)
    pub.publish(msg)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
""")


def symbol_array_roundtrip(domain_id: int) -> SymbolArray:
    """Publish a 1,000-glyph SymbolArray from another process; return what arrived."""
    probe = Probe("symbol_listener", domain_id)
    node, executor = probe.node, probe.executor
    got: list[SymbolArray] = []
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(SymbolArray, "symbols", got.append, qos)
    publisher = subprocess.Popen([sys.executable, "-c", PUBLISHER], env=ros_env(domain_id))
    try:
        assert wait_until(lambda: bool(got), 30.0, lambda: executor.spin_once(timeout_sec=0.05))
    finally:
        stop(publisher)
        probe.close()
    return got[0]


def test_symbol_array_survives_publish_subscribe(domain_id):
    msg = symbol_array_roundtrip(domain_id)
    rng = np.random.default_rng(3)
    n = 1000
    u = rng.uniform(0, 640, n).astype(np.float32)
    v = rng.uniform(0, 480, n).astype(np.float32)
    area = rng.uniform(20, 90, n).astype(np.float32)
    label = rng.integers(0, 3, n).astype(np.uint8)
    label[::7] = SymbolArray.LABEL_UNKNOWN
    confidence = rng.uniform(0, 1, n).astype(np.float32)
    row = rng.integers(-1, 30, n).astype(np.int32)
    col = rng.integers(-1, 30, n).astype(np.int32)
    patches = rng.integers(0, 256, n * 18 * 18).astype(np.uint8)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_700_000_123, 999_999_999)
    assert msg.header.frame_id == "tactile_left_optical_frame"
    assert (msg.image_width, msg.image_height, msg.patch_size) == (640, 480, 18)
    assert msg.spacing_px == pytest.approx(17.25)
    for name, expected in [("u", u), ("v", v), ("area", area), ("label", label),
                           ("confidence", confidence), ("row", row), ("col", col),
                           ("patches", patches)]:
        np.testing.assert_array_equal(np.asarray(getattr(msg, name)), expected, err_msg=name)
