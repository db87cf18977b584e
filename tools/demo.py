"""`make demo`: a bundled bag through the ROS graph, stereo images in, point clouds out.

Starts the installed node executables as separate processes (what `ros2 run` runs), in
namespace /tactile, with localhost-only DDS and a private domain id:

    replay (bag -> left|right/image_raw + camera_info)  ->  decoder (-> points)

The replay is paced by `points` (each stereo frame is sent once the previous frame's cloud
is out), so the throughput printed is what the graph sustains. This process listens to
`points` and `left/symbols_decoded`, compares the clouds with the bag's ground truth, and
writes a decoded-overlay picture and a picture of the point cloud to out/demo/.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import subprocess
import sys
import time

import cv2
import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

from tactile_sl_camera.bag_io import stamp_to_ns
from tactile_sl_camera.clouds import cloud_to_arrays
from tactile_sl_camera.images import to_gray
from tactile_sl_decoder.e2e_metrics import (
    aggregate,
    format_table,
    frame_metrics,
    render_cloud,
    render_overlay,
)
from tactile_sl_decoder.pipeline import PatternSpec, bag_frames, glyphs_from_symbol_array
from tactile_sl_msgs.msg import SymbolArray

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from ros_harness import executable, ros_env, stop  # noqa: E402

DEFAULT_BAG = REPO / "bags" / "two_contacts.mcap"


class Listener:
    """Collects clouds and decoded symbols, with arrival times (monotonic)."""

    def __init__(self, domain_id: int) -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node("demo_listener", namespace="/tactile",
                                      context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self.clouds: dict[int, tuple[float, PointCloud2]] = {}
        self.symbols: dict[int, SymbolArray] = {}
        self.node.create_subscription(PointCloud2, "points", self._on_cloud, qos)
        self.node.create_subscription(SymbolArray, "left/symbols_decoded", self._on_symbols, qos)

    def _on_cloud(self, msg: PointCloud2) -> None:
        self.clouds[stamp_to_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)] = (
            time.monotonic(), msg)

    def _on_symbols(self, msg: SymbolArray) -> None:
        self.symbols[stamp_to_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)] = msg

    def spin(self, seconds: float = 0.05) -> None:
        self.executor.spin_once(timeout_sec=seconds)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def start(package: str, name: str, args: list[str], domain_id: int, log: pathlib.Path
          ) -> subprocess.Popen:
    return subprocess.Popen([str(executable(package, name)), "--ros-args", *args],
                            env=ros_env(domain_id), stdout=open(log, "w"),
                            stderr=subprocess.STDOUT)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bag", type=pathlib.Path, default=DEFAULT_BAG)
    parser.add_argument("--out", type=pathlib.Path, default=REPO / "out" / "demo")
    parser.add_argument("--domain-id", type=int,
                        default=int(os.environ.get("DEMO_DOMAIN_ID", 23)))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    bag = args.bag.resolve()
    print(f"demo: {bag.name} -> replay -> decoder -> points  "
          f"(ROS domain {args.domain_id}, DDS on loopback only)")

    listener = Listener(args.domain_id)
    decoder = start("tactile_sl_decoder", "decoder", ["-r", "__ns:=/tactile"],
                    args.domain_id, args.out / "decoder.log")
    replay = None
    try:
        # Play once this listener is matched with the decoder's `points` publisher (the
        # replay itself waits for the decoder's image subscriptions).
        ready = time.monotonic() + 60
        while listener.node.count_publishers("/tactile/points") < 1 and time.monotonic() < ready:
            listener.spin()
        replay = start("tactile_sl_camera", "replay", [
            "-r", "__ns:=/tactile", "-p", f"bag:={bag}", "-p", "rate:=0.0",
            "-p", "reliability:=reliable", "-p", "depth:=5",
            "-p", "wait_for_subscribers:=1", "-p", "wait_for_subscribers_timeout:=60.0",
            "-p", "wait_for_topic:=points", "-p", "wait_timeout:=5.0"],
            args.domain_id, args.out / "replay.log")
        deadline = time.monotonic() + 180
        while replay.poll() is None and time.monotonic() < deadline:
            listener.spin()
        for _ in range(20):
            listener.spin()
    finally:
        code = stop(replay) if replay is not None else 1
        stop(decoder)
        listener.close()
    if code != 0:
        print(f"demo: replay exited with {code}; see {args.out / 'replay.log'}")
        return 1

    frames = list(bag_frames(bag))
    pattern = PatternSpec.load(None)
    tol = 0.5 * pattern.pitch_m if pattern.pitch_m > 0 else 2.5e-4
    metrics = []
    for frame in frames:
        got = listener.clouds.get(frame.stamp_ns)
        if got is not None and frame.ground_truth is not None:
            metrics.append(frame_metrics(got[1], frame.ground_truth, tol, frame.stamp_ns))
    print(f"\nclouds received: {len(listener.clouds)} of {len(frames)} stereo frames")
    if not metrics:
        print(f"demo: no point cloud came out; see {args.out / 'decoder.log'}")
        return 1
    format_table([aggregate(bag.stem, metrics)])

    arrivals = sorted(t for t, _ in listener.clouds.values())
    if len(arrivals) > 1:
        rate = (len(arrivals) - 1) / (arrivals[-1] - arrivals[0])
        print(f"throughput through the graph: {rate:.1f} stereo frames/s "
              f"(replay waits for each cloud before sending the next frame)")

    # Pictures of the frame with the deepest contact (largest spread of depth).
    depths = {s: cloud_to_arrays(msg)["z"] for s, (_, msg) in listener.clouds.items()}
    stamp = max(depths, key=lambda s: np.ptp(depths[s]) if len(depths[s]) else 0.0)
    frame = next(f for f in frames if f.stamp_ns == stamp)
    cloud = listener.clouds[stamp][1]
    cv2.imwrite(str(args.out / "cloud.png"), render_cloud(cloud))
    if stamp in listener.symbols:
        overlay = render_overlay(to_gray(frame.left_image),
                                 glyphs_from_symbol_array(listener.symbols[stamp]))
        cv2.imwrite(str(args.out / "overlay_left.png"), overlay)
    depth = depths[stamp]
    print(f"\npictures: {args.out.relative_to(REPO) if args.out.is_relative_to(REPO) else args.out}"
          f"/overlay_left.png (glyphs by class, cells annotated), cloud.png "
          f"({cloud.width} points, z {depth.min() * 1e3:.2f}..{depth.max() * 1e3:.2f} mm)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
