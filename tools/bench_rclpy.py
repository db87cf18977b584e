#!/usr/bin/env python3
"""What rclpy costs the decoder per stereo frame, without the pipeline (figures, no verdict).

A sink node with the decoder's inputs (left/right image_raw and camera_info, sensor-data
QoS) receives a bag replayed at a fixed rate and, per stereo frame, does the node's share of
the work around the pipeline: pairs the images by stamp, views them as grey numpy arrays
(``to_gray``), and publishes a cloud of 728 points and a wrench (to a subscriber in this
process, so that they are really built and sent). The process CPU time per stereo frame is
measured for each executor in turn (rclpy's classic single-threaded one and its events
executor, which the nodes use), in the same run; the replay runs in its own process.

    python tools/bench_rclpy.py                       # 60 Hz, 10 s per executor
    python tools/bench_rclpy.py --rate 3 --seconds 20
"""
from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from ros_harness import start_node, stop  # noqa: E402


def measure(kind: str, domain_id: int, seconds: float) -> tuple[float, int]:
    """(CPU ms per stereo frame, frames) of the sink with the executor ``kind``."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image, PointCloud2

    from tactile_sl_common.clouds import cloud_fields, pack_points
    from tactile_sl_common.images import to_gray
    from tactile_sl_common.nodes.messages import cloud_msg

    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node("rclpy_cost_sink", namespace="/tactile", context=context)
    points = pack_points(np.zeros((728, 3)), np.arange(728) // 28, np.arange(728) % 28)
    pub_cloud = node.create_publisher(PointCloud2, "points", 5)
    pub_wrench = node.create_publisher(WrenchStamped, "wrench", 5)
    node.create_subscription(PointCloud2, "points", lambda m: None, 5)
    node.create_subscription(WrenchStamped, "wrench", lambda m: None, 5)
    waiting: dict[str, dict[int, object]] = {"left": {}, "right": {}}
    frames = [0]

    def on_image(side: str, msg: Image) -> None:
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        other = waiting["right" if side == "left" else "left"].pop(stamp, None)
        if other is None:
            waiting[side] = {stamp: msg}
            return
        to_gray(msg)
        to_gray(other)
        frames[0] += 1
        pub_cloud.publish(cloud_msg(cloud_fields(points, (msg.header.stamp.sec,
                                                          msg.header.stamp.nanosec), "left")))
        wrench = WrenchStamped()
        wrench.header = msg.header
        pub_wrench.publish(wrench)

    for side in ("left", "right"):
        node.create_subscription(Image, f"{side}/image_raw",
                                 lambda m, s=side: on_image(s, m), qos_profile_sensor_data)
        node.create_subscription(CameraInfo, f"{side}/camera_info", lambda m: None,
                                 qos_profile_sensor_data)
    executor = (EventsExecutor(context=context) if kind == "events"
                else SingleThreadedExecutor(context=context))
    executor.add_node(node)
    end = time.monotonic() + 3.0                    # discovery, first frames
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    cpu0, n0 = time.process_time(), frames[0]
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    cpu, n = time.process_time() - cpu0, frames[0] - n0
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown(context=context)
    return 1e3 * cpu / max(n, 1), n


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bag", type=pathlib.Path, default=REPO / "bags" / "two_contacts.mcap")
    parser.add_argument("--rate", type=float, default=6.0,
                        help="replay rate multiplier (the bags are 10 Hz: 6 = 60 Hz)")
    parser.add_argument("--seconds", type=float, default=10.0, help="per executor")
    parser.add_argument("--domain-id", type=int,
                        default=int(os.environ.get("BENCH_DOMAIN_ID", 29)))
    args = parser.parse_args()
    replay = start_node("tactile_sl_camera", "replay", args.domain_id, [
        "-r", "__ns:=/tactile", "-p", f"bag:={args.bag}", "-p", "loop:=true",
        "-p", f"rate:={args.rate}", "-p", "wait_for_subscribers:=1"],
        pathlib.Path(os.devnull))
    try:
        results = [(kind, measure(kind, args.domain_id, args.seconds))
                   for kind in ("single", "events", "single", "events")]   # alternating
    finally:
        stop(replay)
    load = os.getloadavg()[0]
    print(f"rclpy per stereo frame at {10 * args.rate:.0f} Hz ({args.bag.name}; receive and "
          f"pair two images and two camera_infos, view the images, publish a cloud and a "
          f"wrench), load average {load:.2f} on {os.cpu_count()} CPUs:")
    for kind, (ms, n) in results:
        name = "SingleThreadedExecutor" if kind == "single" else "EventsExecutor (the nodes')"
        print(f"  {name:<28} {ms:6.2f} ms CPU per frame ({n} frames)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
