"""Several sensors on one robot (issue 12): two replay + decoder pairs at once, one DDS domain.

Each pair runs in its own namespace with its own ``frame_prefix``: its clouds come out on its
own ``points`` in its own camera frame, its touch outputs in its own pad frame, its
diagnostics under its own name and hardware_id, and nothing crosses between the two.
"""
from __future__ import annotations

import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

from ros_harness import BAGS, Probe, next_domain_id, start_looping_sensor, stop

pytestmark = pytest.mark.ros

BAG = BAGS / "no_contact.mcap"
SENSORS = ("left_hand", "right_hand")


def test_two_sensors_in_two_namespaces_have_distinct_frames(tmp_path):
    domain = next_domain_id()
    procs = []
    for name in SENSORS:
        procs += start_looping_sensor(
            domain, ["-r", f"__ns:=/{name}", "-p", f"frame_prefix:={name}_"], BAG, tmp_path, name)
    probe = Probe("several_sensors_test", domain)
    node, executor = probe.node, probe.executor
    got: dict[str, set[str]] = {f"{n}/{kind}": set() for n in SENSORS
                                for kind in ("points", "pad_pose", "wrench")}
    hardware: dict[str, str] = {}
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    for name in SENSORS:
        node.create_subscription(PointCloud2, f"/{name}/points",
                                 lambda m, n=name: got[f"{n}/points"].add(m.header.frame_id),
                                 5)
        node.create_subscription(WrenchStamped, f"/{name}/wrench",
                                 lambda m, n=name: got[f"{n}/wrench"].add(m.header.frame_id),
                                 5)
        node.create_subscription(PoseStamped, f"/{name}/pad_pose",
                                 lambda m, n=name: got[f"{n}/pad_pose"].add(m.header.frame_id),
                                 latched)

    def on_diag(msg: DiagnosticArray) -> None:
        for s in msg.status:
            hardware[s.name.split(": ")[0]] = s.hardware_id
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (all(got.values()) and len(hardware) == 2):
            executor.spin_once(timeout_sec=0.05)
        logs = {p.name: p.read_text()[-1500:] for p in tmp_path.glob("*.log")}
        assert all(got.values()) and len(hardware) == 2, (got, hardware, logs)
        for name in SENSORS:
            assert got[f"{name}/points"] == {f"{name}_tactile_left_optical_frame"}
            # pad_pose: the pad frame's pose in the (prefixed) left optical frame
            assert got[f"{name}/pad_pose"] == {f"{name}_tactile_left_optical_frame"}
            assert got[f"{name}/wrench"] == {f"{name}_tactile_pad"}
            assert hardware[f"{name}/decoder"] == name
    finally:
        probe.close()
        codes = [stop(p) for p in procs]
    assert codes == [0] * len(procs)
