"""Subscriber on another "computer": record every /tactile/points cloud that arrives.

Run by tests/test_robot_network.py inside a network namespace (`ip netns exec`), with the
environment (domain id, discovery range, Fast DDS profile) the test chose. Writes, under
--out:
  ready        once a publisher of /tactile/points has been discovered
  clouds.npz   recv_ns, stamp_ns, point_step, width*height, fields, data of every cloud
Stops after --seconds, --idle seconds without a cloud once one came, --expect clouds, or
when the file --out/stop appears.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import time

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", type=pathlib.Path, required=True)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--idle", type=float, default=3.0)
    parser.add_argument("--expect", type=int, default=0)
    args = parser.parse_args()

    rclpy.init()
    node = rclpy.create_node("points_listener", namespace="/tactile")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    clouds: list[tuple[int, PointCloud2]] = []

    def keep(msg: PointCloud2) -> None:
        clouds.append((time.time_ns(), msg))

    node.create_subscription(PointCloud2, "points", keep,
                             QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
    start = time.monotonic()
    last_count, last_time = 0, start
    publishers_seen = 0
    try:
        while time.monotonic() - start < args.seconds:
            executor.spin_once(timeout_sec=0.02)
            count = node.count_publishers("/tactile/points")
            if count > publishers_seen:
                publishers_seen = count
                (args.out / "ready").write_text(f"{count}\n")
            if len(clouds) != last_count:
                last_count, last_time = len(clouds), time.monotonic()
            elif clouds and time.monotonic() - last_time > args.idle:
                break
            if args.expect and len(clouds) >= args.expect:
                break
            if (args.out / "stop").exists():
                break
    finally:
        fields = [json.dumps([(f.name, f.offset, f.datatype, f.count) for f in m.fields])
                  for _, m in clouds]
        np.savez(args.out / "clouds.npz",
                 recv_ns=np.array([t for t, _ in clouds], dtype=np.int64),
                 stamp_ns=np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
                                    for _, m in clouds], dtype=np.int64),
                 point_step=np.array([m.point_step for _, m in clouds], dtype=np.int64),
                 points=np.array([m.width * m.height for _, m in clouds], dtype=np.int64),
                 fields=np.array(fields, dtype=str),
                 frame_id=np.array([m.header.frame_id for _, m in clouds], dtype=str),
                 data=np.frombuffer(b"".join(bytes(m.data) for _, m in clouds), np.uint8),
                 publishers_seen=np.array(publishers_seen))
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
