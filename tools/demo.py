"""`make demo`: replay a bundled bag through the ROS graph and report what came out.

Starts the installed node executables as separate processes (as `ros2 run` would), in
namespace /tactile, with localhost-only DDS and a private domain id, and listens to their
topics from this process.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import subprocess
import sys
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from ros_harness import executable, ros_env, stop  # noqa: E402

DEFAULT_BAG_ORDER = ("shallow_sphere", "deep_sphere", "no_contact")


def default_bag() -> pathlib.Path:
    bags = sorted((REPO / "bags").glob("*.mcap"))
    if not bags:
        raise SystemExit("no bags in bags/: run `make bags` first")
    for stem in DEFAULT_BAG_ORDER:
        for bag in bags:
            if stem in bag.stem:
                return bag
    return bags[0]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--bag", type=pathlib.Path, default=None)
    parser.add_argument("--domain-id", type=int, default=int(os.environ.get("DEMO_DOMAIN_ID", 23)))
    args = parser.parse_args()
    bag = args.bag or default_bag()
    print(f"demo: replaying {bag.relative_to(REPO) if bag.is_relative_to(REPO) else bag} "
          f"through the ROS graph (domain {args.domain_id}, localhost only)")

    context = Context()
    rclpy.init(context=context, domain_id=args.domain_id)
    node = rclpy.create_node("demo_listener", namespace="/tactile", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    arrivals: dict[str, list[tuple[int, float, object]]] = {}
    for side in ("left", "right"):
        for suffix, kind in (("image_raw", Image), ("camera_info", CameraInfo)):
            topic = f"{side}/{suffix}"
            arrivals[topic] = []
            node.create_subscription(
                kind, topic,
                lambda msg, topic=topic: arrivals[topic].append(
                    (msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec,
                     time.monotonic(), msg)), qos)
    log = open(REPO / "log" / "demo_replay.log", "w") if (REPO / "log").is_dir() else None
    replay = subprocess.Popen(
        [str(executable("tactile_sl_camera", "replay")), "--ros-args", "-r", "__ns:=/tactile",
         "-p", f"bag:={bag}", "-p", "reliability:=reliable", "-p", "depth:=50",
         "-p", "wait_for_subscribers:=1"],
        env=ros_env(args.domain_id), stdout=log or subprocess.DEVNULL, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120
        while replay.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        for _ in range(20):
            executor.spin_once(timeout_sec=0.05)
    finally:
        code = stop(replay)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    if code != 0:
        print(f"demo: replay exited with {code}; see log/demo_replay.log")
        return 1

    print(f"\n{'topic':<26}{'msgs':>6}{'rate Hz':>9}  details")
    for topic, got in arrivals.items():
        if not got:
            print(f"/tactile/{topic:<17}{0:>6}")
            continue
        span = (got[-1][1] - got[0][1]) if len(got) > 1 else 0.0
        rate = (len(got) - 1) / span if span > 0 else float("nan")
        msg = got[-1][2]
        if isinstance(msg, Image):
            detail = f"{msg.width}x{msg.height} {msg.encoding}, frame {msg.header.frame_id}"
        else:
            detail = f"fx={msg.k[0]:.1f} px, P[0,3]={msg.p[3]:.3f}, model {msg.distortion_model}"
        print(f"/tactile/{topic:<17}{len(got):>6}{rate:>9.1f}  {detail}")
    left = [s for s, _, _ in arrivals["left/image_raw"]]
    right = [s for s, _, _ in arrivals["right/image_raw"]]
    paired = len(set(left) & set(right))
    print(f"\nstereo frames with identical left/right stamps: {paired} of {max(len(left), 1)}")
    return 0 if paired and paired == len(left) == len(right) else 1


if __name__ == "__main__":
    sys.exit(main())
