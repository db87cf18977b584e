#!/usr/bin/env python3
"""Benchmarks of the stereo decoding pipeline (figures, not pass/fail tests).

    python tools/bench_pipeline.py                     # in-process timing + accuracy, all bags
    python tools/bench_pipeline.py --flip 0.05         # robustness: 5 % labels flipped
    python tools/bench_pipeline.py --ros --rate 30     # through DDS: decoder node at 30 Hz
    python tools/bench_pipeline.py --sequence --carry both   # 60 Hz sequences, carry on/off

In-process: median milliseconds per stereo pair with the per-stage breakdown (check,
extraction, classification, lattice + decoding, stereo), over every frame of the bags,
and the end-to-end accuracy table (coverage, wrong cells, 3-D error against ground truth).
With --threads 2 (the default) each image runs in its own worker thread: extract, lattice
(k-NN search and neighbourhood of the glyphs + rectification of their centres) and classify
are then the slower worker's times, which overlap; "workers" is the wall time of that part.
With --processes the right image's worker is a process of its own while this process does
the left image's, as in the live decoder node (no interpreter lock shared between the two
images; the image goes through shared memory and its glyphs come back pickled), and
cpu+touch counts the worker's CPU time too.
With touch outputs (the default; --no-touch leaves them out) the touch stage runs after
every frame as in the node and replay ("touch", of which "traction" is the inversion,
"contact" the contact state and "slip" the slip estimate, every output made as replay
writes them: a live node makes the per-cell forces, the contact state and the depth map
only while something subscribes to them; "total+touch"; "cpu+touch" is the process CPU time
of both).  ``--touch-outputs wrench`` times what a live node does for a listener of
``wrench`` alone (a grasp controller): the resultant, no per-cell forces, contact state,
depth map or slip estimate.  In the same run and on the same frames: the floor, the work no
decoder of this design can avoid (threshold + connected components of both images, one
batched classifier pass over the patches the frame had to classify -- all of them with
carry off, those not carried with carry on --, triangulation of the matched cells, the
touch stage's two matrix-vector products), on one thread and with the two images'
labelling in two threads, and total / floor (see docs/decoder.md, "Floor and total / floor").
Each bag runs from its first frame in bag order, once per repetition, so labels are carried
from frame to frame as from a camera (--carry on, the default; off: every glyph classified
every frame; both: the two alternate pass by pass). --sequence benchmarks the camera-rate
sequences of bags/sequence_scenes.yaml instead (rendered into a temporary folder first).

--flip R: after classification, each known label is flipped to another symbol with
probability R (same pipeline otherwise); prints coverage and wrong cells with and without.

--ros: starts the installed ``decoder`` executable (own ROS domain, loopback only),
publishes the bags' stereo frames at --rate Hz for --seconds, each frame stamped with the
current time, and measures latency from image stamp to point cloud received and the frames
that produced no cloud.
"""
from __future__ import annotations

import argparse
import glob
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
FASTDDS_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>shm_large</transport_id>
      <type>SHM</type>
      <segment_size>{size}</segment_size>
    </transport_descriptor>
    <transport_descriptor>
      <transport_id>udp</transport_id>
      <type>UDPv4</type>
      <interfaceWhiteList>
        <address>127.0.0.1</address>
      </interfaceWhiteList>
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="default_participant" is_default_profile="true">
    <rtps>
      <userTransports>
        <transport_id>shm_large</transport_id>
        <transport_id>udp</transport_id>
      </userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
</profiles>
"""


def _profile_label(args: argparse.Namespace) -> str:
    """Which Fast DDS transport settings the --ros run used, for the printed figures."""
    if args.shm_segment_mb > 0:
        return f"temporary, SHM segment {args.shm_segment_mb:g} MB"
    profile = os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE")
    return profile if profile else "none (middleware default, SHM segment 0.5 MB)"


def _bags(args: argparse.Namespace) -> list[str]:
    if args.sequence and not args.bags:
        args.bags = _render_sequences()
    bags = args.bags or sorted(glob.glob(str(REPO / "bags" / "*.mcap")))
    if not bags:
        sys.exit("no bags: run `make bags` or pass bag paths")
    return bags


def _render_sequences() -> list[str]:
    """Render bags/sequence_scenes.yaml (camera-rate sequences) into a temporary folder."""
    import atexit
    import shutil

    out = tempfile.mkdtemp(prefix="tactile_sl_sequences_")
    atexit.register(shutil.rmtree, out, True)
    exe = shutil.which("tactile-sl") or sys.exit("tactile-sl not found: source env.sh")
    print(f"rendering {REPO / 'bags' / 'sequence_scenes.yaml'} (about 15 s per 45 frames)",
          file=sys.stderr)
    subprocess.run([exe, "synth", str(REPO / "bags" / "sequence_scenes.yaml"), "-o", out],
                   check=True)
    return sorted(glob.glob(os.path.join(out, "*.mcap")))


def _pipeline(args: argparse.Namespace, carry: bool = True):
    from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline

    params = PipelineParams(threads=args.threads, cpu_threads=args.cpu_threads,
                            classifier_weights=args.classifier, processes=args.processes)
    params.decode.mirrored = args.mirrored
    params.carry.enabled = carry
    return StereoPipeline(PatternSpec.load(args.pattern), None, params)


def ink_regions(gray: np.ndarray) -> int:
    """The floor's first part for one image: adaptive threshold (no opening) and labelling.

    Returns the number of labels.  ``bench_graph.py`` times it as the machine's speed.
    """
    import cv2

    from tactile_sl_decoder.extract.extraction import ExtractionParams, threshold_ink

    mask = threshold_ink(gray, ExtractionParams(open_size=0))
    return cv2.connectedComponentsWithStatsWithAlgorithm(mask, 8, cv2.CV_32S,
                                                         cv2.CCL_BBDT)[0]


class Floor:
    """The unavoidable work of one stereo pair, timed on the same frames as the pipeline.

    Per pair: the adaptive threshold (box mean minus offset, as the extractor's, without the
    opening) and connected components with statistics on both images, one batched classifier
    pass over as many glyph patches as the frame had to classify (those whose label was not
    carried from the previous frame; every glyph of both images with carry off), the
    triangulation (rectification + linear
    least squares) of the cells both images decoded, and -- with touch outputs -- the touch
    stage's two matrix-vector products (resultant and normal pressure map,
    :meth:`~tactile_sl_decoder.touch.traction.TractionSolver.linear_products`).  ``serial``
    runs it on one thread; ``parallel`` thresholds and labels the two images in two
    threads, as the pipeline's workers do.
    """

    def __init__(self, pipe, parallel: bool) -> None:
        from concurrent.futures import ThreadPoolExecutor

        self.pipe = pipe
        self.pool = ThreadPoolExecutor(max_workers=1) if parallel else None

    def __call__(self, left: np.ndarray, right: np.ndarray, res, rig, solver,
                 disp: np.ndarray | None) -> dict[str, float]:
        """Milliseconds of each part and their sum (``floor``) for one stereo pair."""
        cols = self.pipe.codebook.cols
        patches = [g.patches for g in (res.left, res.right) if g.patches is not None and len(g)]
        patches = np.concatenate(patches) if patches else np.zeros((0, 18, 18), np.uint8)
        cl = np.where(res.left.row >= 0, res.left.row.astype(np.int64) * cols + res.left.col,
                      -1)
        cr = np.where(res.right.row >= 0,
                      res.right.row.astype(np.int64) * cols + res.right.col, -1)
        il, ir = np.flatnonzero(cl >= 0), np.flatnonzero(cr >= 0)
        _, a, b = np.intersect1d(cl[il], cr[ir], assume_unique=True, return_indices=True)
        uv_l = np.column_stack([res.left.u, res.left.v]).astype(np.float64)[il[a]]
        uv_r = np.column_stack([res.right.u, res.right.v]).astype(np.float64)[ir[b]]
        classifier = self.pipe.load_classifier()
        # exactly as many glyphs as this frame had to classify: those not carried from the
        # previous frame (all of them with carry off or after a jump)
        patches = patches[:max(len(patches) - res.carried, 0)]
        t0 = time.perf_counter()
        if self.pool is None:
            ink_regions(left)
            ink_regions(right)
        else:
            fut = self.pool.submit(ink_regions, right)
            ink_regions(left)
            fut.result()
        t1 = time.perf_counter()
        classifier.predict(patches)
        t2 = time.perf_counter()
        rig.triangulate(uv_l, uv_r)
        t3 = time.perf_counter()
        if solver is not None and disp is not None:
            u = disp.reshape(-1)
            solver.linear_products(u, u.astype(np.float32))
        t4 = time.perf_counter()
        out = {"threshold+cc": t1 - t0, "classify": t2 - t1, "triangulate": t3 - t2,
               "touch mat-vec": t4 - t3, "floor": t4 - t0}
        return {k: 1e3 * v for k, v in out.items()}

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()


def in_process(args: argparse.Namespace) -> int:  # noqa: C901 - a report script, top to bottom
    """Per-stage timing over all frames, the floor, and the accuracy table.

    Each bag is run ``warmup + repeat`` times from its first frame, frames in bag order (as
    a camera delivers them: labels carried from frame to frame, see classify/carry.py), a
    fresh touch reference per pass.  With ``--carry both`` the pipeline with and without
    carried labels alternate pass by pass, so their figures come from the same sitting.
    """
    from tactile_sl_common.images import to_gray
    from tactile_sl_decoder.cpu_threads import set_cpu_threads
    from tactile_sl_decoder.frames import bag_frames
    from tactile_sl_decoder.tooling.e2e_metrics import aggregate, format_table, frame_metrics

    set_cpu_threads(args.cpu_threads)   # OpenCV and OpenBLAS, as the pipeline does
    modes = ["on", "off"] if args.carry == "both" else [args.carry]
    pipes = {m: _pipeline(args, carry=m == "on") for m in modes}
    first = pipes[modes[0]]
    floors = {"serial": Floor(first, parallel=False), "parallel": Floor(first, parallel=True)}
    stages = ("check", "extract", "lattice", "classify", "workers", "decode", "stereo", "total")
    touch_rows = ["touch", "traction", "contact", "slip", "total+touch", "cpu+touch"]
    rows = list(stages) + (touch_rows if args.touch else [])
    timings: dict[str, dict[str, list[float]]] = {m: {s: [] for s in rows} for m in modes}
    carried: dict[str, list[float]] = {m: [] for m in modes}
    floor_t: dict[str, dict[str, list[float]]] = {k: {} for k in floors}
    paired: dict[str, dict[str, list[float]]] = {m: {"total": [], "total+touch": []}
                                                 for m in modes}   # as the floors
    tables: dict[str, list] = {m: [] for m in modes}
    glyphs = []
    points_at: list[float] = []        # when each frame's points were ready (before touch)

    def points_ready(_result) -> None:
        points_at.append(time.perf_counter())

    load0 = os.getloadavg()
    t_run = time.perf_counter()
    for bag in _bags(args):
        frames = [(fr, to_gray(fr.left_image), to_gray(fr.right_image))
                  for fr in bag_frames(bag)]
        for rep in range(args.warmup + args.repeat):
            timed = rep >= args.warmup
            last = rep == args.warmup + args.repeat - 1
            for mode in (modes if rep % 2 else modes[::-1]):   # alternate which runs first
                pipe = pipes[mode]
                step = _sensor_step(pipe, args.touch)   # a fresh touch reference per pass
                step.forget_frames()
                stage = step.touch.stage if step.touch is not None else None
                every_output = args.touch_outputs == "all"
                if stage is not None and not every_output:
                    stage.slip_wanted = lambda: False  # as the node without a slip listener
                metrics = []
                for fr, left, right in frames:
                    c0 = _cpu_seconds(pipe)
                    t0 = time.perf_counter()
                    out = step.process(left, right, fr.left_info, fr.right_info,
                                       on_points=points_ready)
                    res, touch = out.stereo, out.touch.result
                    if touch is not None and every_output:   # as replay writes them
                        _ = touch.contact, touch.depth
                    t2 = time.perf_counter()
                    c1 = _cpu_seconds(pipe)
                    t1 = points_at[-1]
                    if last and fr.ground_truth is not None:
                        metrics.append(frame_metrics(res.points, fr.ground_truth,
                                                     0.5 * pipe.pattern.pitch_m, fr.stamp_ns))
                    if not timed:
                        continue
                    t = timings[mode]
                    for s in stages:
                        t[s].append(res.timings_ms.get(s, 0.0))
                    n = len(res.left) + len(res.right)
                    carried[mode].append(res.carried / n if n else 0.0)
                    if mode == modes[0]:
                        glyphs.append(n)
                    if stage is not None and touch is None:
                        continue                         # only frames with touch outputs
                    if args.touch:
                        t["touch"].append(1e3 * (t2 - t1))
                        if touch is not None:           # parts of the touch stage
                            for part in ("traction", "contact", "slip"):
                                t[part].append(touch.timings_ms[part])
                        t["total+touch"].append(1e3 * (t2 - t0))
                        t["cpu+touch"].append(1e3 * (c1 - c0))
                    paired[mode]["total"].append(res.timings_ms["total"])
                    paired[mode]["total+touch"].append(1e3 * (t2 - t0))
                    if mode != modes[0]:
                        continue
                    solver = stage.solver if stage is not None else None
                    disp = stage.last_solve[0] if stage is not None and stage.last_solve else None
                    order = list(floors) if rep % 2 else list(floors)[::-1]
                    for name in order:
                        parts = floors[name](left, right, res, pipe.rig(fr.left_info,
                                                                        fr.right_info),
                                             solver, disp)
                        for k, v in parts.items():
                            floor_t[name].setdefault(k, []).append(v)
                if metrics:
                    tables[mode].append(aggregate(pathlib.Path(bag).stem, metrics))
    load1 = os.getloadavg()
    n_pairs = len(timings[modes[0]]["total"])
    print(f"in-process, {n_pairs} stereo pairs per setting (median glyphs per pair "
          f"{int(np.median(glyphs))}), "
          f"{'camera processes' if args.processes else f'threads={args.threads}'}, "
          f"cpu_threads={args.cpu_threads}, "
          f"{time.perf_counter() - t_run:.0f} s; load average {load0[0]:.2f} before, "
          f"{load1[0]:.2f} after, on {os.cpu_count()} CPUs")
    if args.touch:
        print("touch outputs made per frame: " + (
            "all (per-cell forces, contact state, depth map, slip), as replay writes them"
            if args.touch_outputs == "all" else
            "the wrench only, as the node makes it for a wrench listener alone"))
    for mode in modes:
        print(f"labels carried from the previous frame: {mode} (median "
              f"{100 * np.median(carried[mode]):.1f} % of the glyphs per pair)")
        print(f"{'stage':<14} {'median ms':>10} {'p90 ms':>8} {'min ms':>8}")
        for s in rows:
            _row(s, timings[mode][s])
    which = "pairs with touch outputs" if args.touch else "all pairs"
    for name, parts in floor_t.items():
        print(f"floor, {name} ({'one thread' if name == 'serial' else 'two images in two threads'},"
              f" {which}):")
        for k, v in parts.items():
            if args.touch or k != "touch mat-vec":
                _row("  " + k, v)
    print(f"total / floor, {which} (ratio of medians; median of the per-pair ratios; the "
          f"floor measured beside carry {modes[0]}):")
    for name, parts in floor_t.items():
        fl = np.asarray(parts["floor"]) if parts else np.full(1, np.nan)
        for mode in modes:
            for label in (("total", "total+touch") if args.touch else ("total",)):
                tot = np.asarray(paired[mode][label])
                ratio = (f"{np.median(tot / fl):.2f}" if len(tot) == len(fl)
                         else "paired n/a")
                print(f"  carry {mode:<3} {label:<12} / floor {name:<8} "
                      f"{np.median(tot) / np.median(fl):>5.2f} ({ratio})")
    for mode in modes:
        if tables[mode]:
            print(f"\naccuracy, carry {mode}:")
            format_table(tables[mode])
    for f in floors.values():
        f.close()
    for pipe in pipes.values():
        pipe.close()
    return 0


def _cpu_seconds(pipe) -> float:
    """CPU seconds of this process and, with camera processes, of its worker processes.

    The workers' from /proc/<pid>/task/*/schedstat (nanoseconds on the CPU; the tick-based
    counters of /proc/<pid>/stat are too coarse for one frame).
    """
    total = time.process_time()
    for pid in pipe.worker_pids:
        for task in pathlib.Path(f"/proc/{pid}/task").glob("*/schedstat"):
            try:
                total += int(task.read_text().split()[0]) * 1e-9
            except (OSError, ValueError, IndexError):
                pass                       # a thread that just ended
    return total


def _row(label: str, values: list[float]) -> None:
    v = np.asarray(values)
    if len(v) == 0:
        return
    print(f"{label:<14} {np.median(v):>10.2f} {np.percentile(v, 90):>8.2f} {v.min():>8.2f}")


def _sensor_step(pipe, touch: bool):
    """The sensor step as replay runs it, touch outputs with the shipped sensor if ``touch``.

    The reference is the first frame; a failed reference starts a new one.
    """
    from tactile_sl_decoder.sensor_step import SensorStep
    from tactile_sl_decoder.touch.sensor import load_sensor
    from tactile_sl_decoder.touch.stage import TouchParams

    return SensorStep(pipe, load_sensor(None) if touch else None,
                      TouchParams(reference_frames=1))


def flips(args: argparse.Namespace) -> int:
    """Coverage and wrong cells with and without random label flips."""
    from tactile_sl_decoder.cpu_threads import set_cpu_threads
    from tactile_sl_decoder.tooling.bag_runs import evaluate_bag, flip_labels_hook

    set_cpu_threads(args.cpu_threads)   # OpenCV and OpenBLAS, as the pipeline does
    pipe = _pipeline(args)
    print(f"label-flip robustness: {100 * args.flip:.1f} % of known labels flipped after "
          f"classification (seed {args.seed})")
    print(f"{'bag':<24} {'coverage':>9} {'flipped':>9} {'drop pts':>9} {'wrong':>6} "
          f"{'wrong flipped':>14} {'wrong%':>7}")
    worst = 0.0
    for bag in _bags(args):
        _, base = evaluate_bag(bag, pipe)
        _, flip = evaluate_bag(bag, pipe, label_hook=flip_labels_hook(args.flip, 3, args.seed))
        drop = 100 * (base.coverage - flip.coverage)
        worst = max(worst, drop)
        print(f"{base.name:<24} {100 * base.coverage:>8.2f}% {100 * flip.coverage:>8.2f}% "
              f"{drop:>9.2f} {base.wrong:>6} {flip.wrong:>14} {100 * flip.wrong_rate:>6.3f}%")
    print(f"largest coverage drop: {worst:.2f} points")
    pipe.close()
    return 0


def through_ros(args: argparse.Namespace) -> int:  # noqa: C901 - a report script, top to bottom
    """Decoder node fed at a fixed rate over loopback DDS: drops and latency."""
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CameraInfo, Image, PointCloud2

    from tactile_sl_common.bag_io import BagReader

    exe = REPO / "install" / "tactile_sl_decoder" / "lib" / "tactile_sl_decoder" / "decoder"
    domain = 150 + os.getpid() % 50
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    if args.shm_segment_mb > 0:
        # Fast DDS's default 512 KB shared-memory segment holds one 640x480 image: the left
        # image of a frame is recycled when the right one is written right after it. UDP on
        # loopback only, like config/fastdds_loopback.xml.
        profile = pathlib.Path(tempfile.mkdtemp()) / "fastdds_loopback.xml"
        profile.write_text(FASTDDS_PROFILE.format(size=int(args.shm_segment_mb * 2**20)))
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(profile)
        os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(profile)   # this process too
    cmd = [str(exe), "--ros-args", "-r", "__ns:=/tactile", "-p", f"threads:={args.threads}",
           "-p", f"cpu_threads:={args.cpu_threads}", "-p", "publish_symbols:=false"]
    if args.pattern:
        cmd += ["-p", f"pattern_file:={args.pattern}"]
    frames = []   # (left image, right image, left info, right info)
    for bag in _bags(args):
        parts: dict[tuple[int, int], dict[str, object]] = {}
        for raw in BagReader(bag).raw_messages():
            side = "left" if "/left/" in raw.topic else "right"
            if raw.topic.endswith("image_raw"):
                m = deserialize_message(raw.data, Image)
                key = "img_" + side
            elif raw.topic.endswith("camera_info"):
                m = deserialize_message(raw.data, CameraInfo)
                key = "info_" + side
            else:
                continue
            parts.setdefault((m.header.stamp.sec, m.header.stamp.nanosec), {})[key] = m
        frames += [p for _, p in sorted(parts.items()) if len(p) == 4]
    log = open(args.node_log, "w") if args.node_log else subprocess.DEVNULL
    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
    rclpy.init(domain_id=domain)
    node = Node("bench_pipeline")
    pubs = {k: node.create_publisher(Image if k.startswith("img") else CameraInfo,
                                     f"/tactile/{k.split('_')[1]}/"
                                     f"{'image_raw' if k.startswith('img') else 'camera_info'}",
                                     qos_profile_sensor_data)
            for k in ("img_left", "img_right", "info_left", "info_right")}
    received: dict[int, float] = {}
    widths: list[int] = []

    def on_cloud(msg: PointCloud2) -> None:
        received[msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec] = time.time()
        widths.append(msg.width)

    node.create_subscription(PointCloud2, "/tactile/points", on_cloud, 50)
    try:
        end = time.monotonic() + 60
        while time.monotonic() < end and not all(
                p.get_subscription_count() for p in pubs.values()):
            rclpy.spin_once(node, timeout_sec=0.05)
        # Warm-up frames (imports, first allocations) are not measured.
        sent: list[int] = []
        period = 1.0 / args.rate
        n_total = int(args.seconds * args.rate)
        t_next = time.monotonic() + 0.5
        for i in range(args.warmup_frames + n_total):
            fr = frames[i % len(frames)]
            while time.monotonic() < t_next:
                rclpy.spin_once(node, timeout_sec=max(0.0, t_next - time.monotonic()))
            t_next += period
            now = time.time_ns()
            stamp = (now // 10**9, now % 10**9)
            for key in ("info_left", "info_right", "img_left", "img_right"):
                m = fr[key]
                m.header.stamp.sec, m.header.stamp.nanosec = stamp
                pubs[key].publish(m)
                if key == "img_left" and args.gap_ms > 0:
                    time.sleep(args.gap_ms / 1e3)
            if i >= args.warmup_frames:
                sent.append(now)
        drain = time.monotonic() + 2.0
        while time.monotonic() < drain:
            rclpy.spin_once(node, timeout_sec=0.05)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        proc.terminate()
        proc.wait(10)
    lat = np.array([1e3 * (received[s] - s / 1e9) for s in sent if s in received])
    dropped = sum(1 for s in sent if s not in received)
    print(f"through ROS (loopback DDS): {len(sent)} stereo frames at {args.rate:.0f} Hz, "
          f"threads={args.threads}, cpu_threads={args.cpu_threads}, load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    print(f"clouds received {len(lat)}, frames without a cloud (dropped) {dropped}; "
          f"Fast DDS profile: {_profile_label(args)}")
    if len(lat):
        print(f"latency stamp -> cloud received: median {np.median(lat):.1f} ms, "
              f"p99 {np.percentile(lat, 99):.1f} ms, max {lat.max():.1f} ms; "
              f"median points per cloud {int(np.median(widths))}")
    return 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bags", nargs="*", help="bags (default: bags/*.mcap)")
    p.add_argument("--pattern", default=None, help="pattern YAML (default: the shipped one)")
    p.add_argument("--mirrored", action="store_true")
    p.add_argument("--threads", type=int, default=2,
                   help="pipeline worker threads for the two images (default 2, as the node)")
    p.add_argument("--processes", action="store_true",
                   help="each camera's extraction, k-NN and classification in a worker "
                        "process, as the live decoder node runs them (default: --threads); "
                        "cpu+touch then adds the workers' CPU time")
    p.add_argument("--cpu-threads", type=int, default=1,
                   help="OpenCV / BLAS intra-op threads (0 = library defaults)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs per frame")
    p.add_argument("--warmup", type=int, default=1, help="untimed runs per frame first")
    p.add_argument("--classifier", default=None, metavar="WEIGHTS",
                   help="classifier weights (default: the shipped ones, data/classifier.pt; "
                   "LeNet-5: data/classifier_lenet5.pt)")
    p.add_argument("--carry", choices=("on", "off", "both"), default="on",
                   help="labels carried from the previous frame (both: alternate passes)")
    p.add_argument("--sequence", action="store_true",
                   help="the camera-rate sequences of bags/sequence_scenes.yaml (rendered "
                        "first) instead of the bundled bags")
    p.add_argument("--no-touch", dest="touch", action="store_false",
                   help="time the pipeline alone (default: also the touch stage, "
                   "TouchStage.update after every frame, as the node and replay)")
    p.add_argument("--touch-outputs", choices=("all", "wrench"), default="all",
                   help="touch outputs made per frame: all (as replay writes them; default) "
                        "or only the wrench (as the node for a wrench listener alone)")
    p.add_argument("--flip", type=float, default=0.0, help="label-flip robustness run")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--ros", action="store_true", help="measure through the ROS graph")
    p.add_argument("--rate", type=float, default=30.0, help="--ros input rate, Hz")
    p.add_argument("--seconds", type=float, default=10.0, help="--ros measured duration")
    p.add_argument("--warmup-frames", type=int, default=10, help="--ros unmeasured frames")
    p.add_argument("--node-log", default="", help="--ros: write the decoder's output here")
    p.add_argument("--shm-segment-mb", type=float, default=0.0,
                   help="--ros: Fast DDS shared-memory segment size written to a temporary "
                   "profile (0 = use $FASTRTPS_DEFAULT_PROFILES_FILE as set by env.sh, 16 MB; "
                   "without a profile the middleware's 512 KB loses left images of "
                   "back-to-back stereo pairs)")
    p.add_argument("--gap-ms", type=float, default=0.0,
                   help="--ros: pause between publishing the left and the right image")
    args = p.parse_args()
    if args.ros:
        return through_ros(args)
    if args.flip > 0:
        return flips(args)
    return in_process(args)


if __name__ == "__main__":
    sys.exit(main())
