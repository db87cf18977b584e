"""`make demo`: a bundled bag through the ROS graph, stereo images in, points and touch out.

Starts the installed node executables as separate processes (what `ros2 run` runs), in
namespace /tactile, with localhost-only DDS and a private domain id:

    replay (bag -> left|right/image_raw + camera_info)
        ->  decoder (-> points, field, wrench, contact, depth, slip)

The default bag, bags/touch_halfspace.mcap, presses a known load (0.05 to 2 N, then sheared
and twisted) on the simulated pad; its first frame is the untouched reference.  The replay
is paced by `points` (each stereo frame is sent once the previous frame's cloud is out), so
the throughput printed is what the graph sustains. This process listens to `points`,
`left/symbols_decoded` and the touch topics, compares them with the bag's ground truth
(coverage, wrong cells, 3-D error; force, shear, centroid, area, depth, in_contact), and
writes to out/demo/ a decoded-overlay picture, a picture of the point cloud, the pressure
map with shear arrows and the depth map of the most loaded frame.

With ``--view`` (``make demo VIEW=1``) the ``viewer`` node runs beside them and its address
is printed; after the report the bag keeps playing in a loop at its recorded rate through a
fresh decoder, for the page, until Ctrl-C (or ``--view-seconds``).
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
from geometry_msgs.msg import WrenchStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, PointCloud2

from tactile_sl_common.bag_io import stamp_to_ns
from tactile_sl_common.clouds import FIELD_FORCE_DTYPE, cloud_to_arrays
from tactile_sl_common.images import to_gray
from tactile_sl_decoder.frames import bag_frames
from tactile_sl_decoder.pipeline import PatternSpec
from tactile_sl_decoder.symbol_array import from_message
from tactile_sl_decoder.tooling.e2e_metrics import aggregate, format_table, frame_metrics
from tactile_sl_decoder.tooling.pictures import (
    render_cloud,
    render_depth,
    render_overlay,
    render_pressure,
)
from tactile_sl_decoder.tooling.touch_metrics import (
    has_touch_truth,
    read_truths,
    resolve_sensor,
    sensor_text,
)
from tactile_sl_decoder.touch.contact import depth_grid
from tactile_sl_decoder.touch.sensor import SensorFileError, sensor_yaml_text
from tactile_sl_msgs.msg import Contact, SymbolArray

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from ros_harness import executable, ros_env, stop  # noqa: E402

DEFAULT_BAG = REPO / "bags" / "touch_halfspace.mcap"
TOUCH = {"field": PointCloud2, "wrench": WrenchStamped, "contact": Contact, "depth": Image}


def _ns(header: object) -> int:
    return stamp_to_ns(header.stamp.sec, header.stamp.nanosec)  # type: ignore[attr-defined]


class Listener:
    """Collects clouds, decoded symbols and touch outputs, with arrival times (monotonic)."""

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
        self.touch: dict[str, dict[int, object]] = {name: {} for name in TOUCH}
        for name, kind in TOUCH.items():
            self.node.create_subscription(
                kind, name, lambda m, n=name: self.touch[n].__setitem__(_ns(m.header), m), qos)

    def _on_cloud(self, msg: PointCloud2) -> None:
        self.clouds[stamp_to_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)] = (
            time.monotonic(), msg)

    def _on_symbols(self, msg: SymbolArray) -> None:
        self.symbols[stamp_to_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)] = msg

    def touch_complete(self, reference_frames: int = 1) -> bool:
        """Every decoded frame after the reference has all four touch outputs."""
        stamps = sorted(s for s, (_, msg) in self.clouds.items() if msg.width)
        return all(set(stamps[reference_frames:]) <= set(got) for got in self.touch.values())

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
    parser.add_argument("--sensor", type=pathlib.Path, default=None,
                        help="sensor file for the decoder (default: the elastomer of the bag's "
                        "scene in bags/*scenes.yaml, else the shipped one)")
    parser.add_argument("--out", type=pathlib.Path, default=REPO / "out" / "demo")
    parser.add_argument("--domain-id", type=int,
                        default=int(os.environ.get("DEMO_DOMAIN_ID", 23)))
    parser.add_argument("--view", action="store_true",
                        help="also start the viewer (browser page) and keep the bag playing "
                        "for it after the report")
    parser.add_argument("--view-port", type=int, default=8080,
                        help="port of the viewer's page (default 8080, on 127.0.0.1)")
    parser.add_argument("--view-seconds", type=float, default=0.0,
                        help="with --view: stop after this long (0 = at Ctrl-C)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    bag = args.bag.resolve()
    try:
        sensor, sensor_from = resolve_sensor(bag, args.sensor)
    except SensorFileError as exc:
        print(f"demo: {exc}")
        return 1
    sensor_file = args.out / "sensor.yaml"
    sensor_file.write_text(sensor_yaml_text(sensor, f"demo: {sensor_from}"))
    print(f"demo: {bag.name} -> replay -> decoder -> points + touch  "
          f"(ROS domain {args.domain_id}, DDS on loopback only)")
    print(f"sensor: {sensor_text(sensor)} ({sensor_from})")

    viewer = start_viewer(args) if args.view else None
    if args.view and viewer is None:
        return 1
    listener = Listener(args.domain_id)
    decoder = start("tactile_sl_decoder", "decoder",
                    ["-r", "__ns:=/tactile", "-p", f"sensor_file:={sensor_file}"],
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
        # Every frame after the reference gets touch outputs, those that came while the
        # reference was being prepared (about a second after the first frame) a little later.
        deadline = time.monotonic() + 60
        while not listener.touch_complete() and time.monotonic() < deadline:
            listener.spin()
        for _ in range(5):
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
    print(f"\nclouds received: {len(listener.clouds)} of {len(frames)} stereo frames; "
          f"touch outputs for {len(listener.touch['wrench'])} (the first frame is the "
          "untouched reference)")
    if not listener.touch_complete():
        print("demo: some frames after the reference got no touch outputs; see "
              f"{args.out / 'decoder.log'}")
    if not metrics:
        print(f"demo: no point cloud came out; see {args.out / 'decoder.log'}")
        return 1
    truths = read_truths(bag) if has_touch_truth(bag) else {}
    print_frames(frames, metrics, listener, truths)
    print()
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
                                 from_message(listener.symbols[stamp]))
        cv2.imwrite(str(args.out / "overlay_left.png"), overlay)
    depth = depths[stamp]
    where = args.out.relative_to(REPO) if args.out.is_relative_to(REPO) else args.out
    print(f"\npictures: {where}/overlay_left.png (glyphs by class, cells annotated), "
          f"cloud.png ({cloud.width} points, z {depth.min() * 1e3:.2f}..{depth.max() * 1e3:.2f} "
          "mm)")
    touch_pictures(listener, pattern, frames[0].stamp_ns, args.out, where)
    if viewer is not None:
        return serve_view(args, bag, sensor_file, viewer)
    return 0


_VIEWERS: list[subprocess.Popen] = []     # stopped however the demo ends


def start_viewer(args: argparse.Namespace) -> tuple[subprocess.Popen, str] | None:
    """The viewer node beside the demo, and its address (from its log)."""
    log = args.out / "viewer.log"
    proc = start("tactile_sl_viewer", "viewer",
                 ["-r", "__ns:=/tactile", "-p", f"port:={args.view_port}"], args.domain_id, log)
    _VIEWERS.append(proc)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and proc.poll() is None:
        text = log.read_text(errors="replace") if log.exists() else ""
        if "viewer: open " in text:
            url = text.split("viewer: open ", 1)[1].split()[0]
            print(f"viewer: open {url} in a browser on this computer")
            return proc, url
        time.sleep(0.1)
    stop(proc)
    print(f"demo: the viewer did not start; see {log}")
    return None


def serve_view(args: argparse.Namespace, bag: pathlib.Path, sensor_file: pathlib.Path,
               viewer: tuple[subprocess.Popen, str]) -> int:
    """Keep the bag playing (looped, recorded rate) through a fresh decoder for the page."""
    proc, url = viewer
    decoder = start("tactile_sl_decoder", "decoder",
                    ["-r", "__ns:=/tactile", "-p", f"sensor_file:={sensor_file}"],
                    args.domain_id, args.out / "decoder_view.log")
    replay = start("tactile_sl_camera", "replay", [
        "-r", "__ns:=/tactile", "-p", f"bag:={bag}", "-p", "loop:=true", "-p", "rate:=1.0",
        "-p", "wait_for_subscribers:=1", "-p", "wait_for_subscribers_timeout:=60.0"],
        args.domain_id, args.out / "replay_view.log")
    how = f"for {args.view_seconds:g} s" if args.view_seconds > 0 else "until Ctrl-C"
    print(f"\nviewer: {bag.name} plays in a loop at its recorded rate {how}: {url}")
    end = time.monotonic() + args.view_seconds if args.view_seconds > 0 else float("inf")
    try:
        while time.monotonic() < end and all(p.poll() is None for p in (proc, decoder, replay)):
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        for p in (replay, decoder, proc):
            stop(p)
    return 0


def print_frames(frames: list, metrics: list, listener: Listener, truths: dict) -> None:
    """One line per frame: coverage beside force and contact (estimate, truth in brackets)."""
    by_stamp = {m.stamp_ns: m for m in metrics}
    t0 = frames[0].stamp_ns - frames[0].stamp_ns % 1_000_000_000 if frames else 0
    print("per frame: estimate [truth]; Fn normal force, shear (Fx, Fy), centroid (x, y), "
          "pad frame")
    print(f"{'t s':>5} {'coverage':>8} {'wrong':>5} {'rmse mm':>7}  {'Fn N':<16} "
          f"{'shear mN':<30} {'centroid mm':<28} {'area mm2':<14} {'depth um':<11} contact")
    for frame in frames:
        s = frame.stamp_ns
        m = by_stamp.get(s)
        head = (f"{(s - t0) / 1e9:>5.1f} " + (f"{100 * m.coverage:>7.1f}% {m.wrong:>5} "
                                              f"{1e3 * m.summary()['rmse_m']:>7.4f}  "
                                              if m else f"{'-':>8} {'-':>5} {'-':>7}  "))
        w, c = listener.touch["wrench"].get(s), listener.touch["contact"].get(s)
        if w is None or c is None:
            print(head + "(reference frame: no touch output)")
            continue
        t = truths.get(s)
        f = w.wrench.force
        tr = (lambda text: f"[{text}]") if t is not None else (lambda text: "")
        tf = t.force if t is not None and t.force is not None else None
        fn = f"{-f.z:.3f}" + (tr(f"{-tf[2]:.3f}") if tf is not None else "")
        sh = f"{1e3 * f.x:+.1f},{1e3 * f.y:+.1f}" + (
            tr(f"{1e3 * tf[0]:+.1f},{1e3 * tf[1]:+.1f}") if tf is not None else "")
        ce = f"{1e3 * c.centroid.x:+.3f},{1e3 * c.centroid.y:+.3f}" + (
            tr(f"{1e3 * t.centroid[0]:+.3f},{1e3 * t.centroid[1]:+.3f}") if t else "")
        ar = f"{1e6 * c.area:.1f}" + (tr(f"{1e6 * t.area:.1f}") if t else "")
        de = f"{1e6 * c.max_depth:.0f}" + (tr(f"{1e6 * t.max_depth:.0f}") if t else "")
        co = str(c.in_contact) + (tr(str(t.in_contact)) if t else "")
        print(head + f"{fn:<16} {sh:<30} {ce:<28} {ar:<14} {de:<11} {co}")


def touch_pictures(listener: Listener, pattern: PatternSpec, t0_ns: int, out: pathlib.Path,
                   where: object) -> None:
    """pressure.png and depth.png of the most loaded frame (largest |force|)."""
    wrenches = listener.touch["wrench"]
    have = [s for s in wrenches if s in listener.touch["field"] and s in listener.touch["depth"]]
    if not have:
        print("no touch output came out: no pressure or depth picture")
        return
    stamp = max(have, key=lambda s: np.hypot(np.hypot(wrenches[s].wrench.force.x,
                                                       wrenches[s].wrench.force.y),
                                              wrenches[s].wrench.force.z))
    f = wrenches[stamp].wrench.force
    t = (stamp - t0_ns + t0_ns % 1_000_000_000) / 1e9
    label = f"t {t:.1f} s, Fn {-f.z:.3f} N, shear ({1e3 * f.x:+.0f}, {1e3 * f.y:+.0f}) mN"
    field = cloud_to_arrays(listener.touch["field"][stamp], FIELD_FORCE_DTYPE)
    cv2.imwrite(str(out / "pressure.png"), render_pressure(
        field, pattern.pitch_m, f"pressure per cell (kPa) and shear, pad frame; {label}"))
    msg = listener.touch["depth"][stamp]
    depth = np.frombuffer(bytes(msg.data), dtype="<f4").reshape(msg.height, msg.width)
    rows, cols = pattern.array.shape
    grid = depth_grid((rows, cols), pattern.pitch_m, max(1, (msg.width - 1) // max(cols - 1, 1)))
    cv2.imwrite(str(out / "depth.png"), render_depth(
        depth, grid.x0, grid.y0, grid.resolution, f"depth map (um), pad frame; {label}"))
    print(f"          {where}/pressure.png (pressure per cell, shear arrows) and depth.png "
          f"(indentation, grey = not decoded), most loaded frame ({label})")


if __name__ == "__main__":
    try:
        sys.exit(main())
    finally:
        for viewer_process in _VIEWERS:
            stop(viewer_process)
