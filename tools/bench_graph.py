"""Through the ROS graph: `replay` -> `decoder` at a fixed input rate; drops and latency.

Both are the installed executables, run as separate processes (namespace /tactile, or one
namespace per sensor with ``--sensors N``: N replay + decoder pairs on one machine, as on a
hand with several sensors; loopback DDS, private domain). The replay restamps every stereo
frame with the time it is published, so latency = arrival time of the cloud here - its
stamp. A frame is dropped if no cloud with its stamp arrives. This listener also subscribes
to every decoder's ``wrench`` (what a grasp controller reads): the same for the touch outputs,
every frame after the reference (the first) is expected to get one. Latency and drops are
printed over all frames and over those stamped ``--settle`` seconds after the first cloud
(without the one-time start: DDS discovery, first allocations, the touch reference's
preparation, during which frames wait and get their wrench late). Figures, not a pass/fail
test.

    python tools/bench_graph.py --rate 3 --seconds 60    # 30 Hz for 60 s
    python tools/bench_graph.py --rate 6 --seconds 60    # 60 Hz
    python tools/bench_graph.py --rate 3 --seconds 60 --sensors 2
    python tools/bench_graph.py --rate 6 --seconds 600   # resident memory over 10 min
    tactile-sl synth bags/sequence_scenes.yaml -o /tmp/seq  # a 60 Hz press (45 frames)
    python tools/bench_graph.py --bag /tmp/seq/press_60hz.mcap --rate 1 --seconds 60

With ``--sensors N`` the decoders get what ``sensors.launch.py`` gives N sensors on this
machine (:func:`~tactile_sl_decoder.nodes.sensors.decoder_overrides`: in process on one
thread where there are fewer than two cores per sensor); ``--param`` overrides it.

Also printed: CPU use of every decoder and replay process over the run (per cent of one
CPU) and their resident memory when the first cloud arrives and at the end, each with its
descendants (the decoder's camera worker processes); and, measured before the nodes start,
the machine's speed at that moment: the median time of the adaptive threshold and connected
components of the bag's first stereo pair on one thread (the floor's first part in
``bench_pipeline.py``).  A shared VM's speed moves by 1.5x and more within hours, and that
figure lets runs of different sittings be compared.
"""
from __future__ import annotations

import argparse
import math
import os
import pathlib
import subprocess
import sys
import time

import numpy as np
import rclpy
from geometry_msgs.msg import WrenchStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

from tactile_sl_common.bag_io import stamp_to_ns
from tactile_sl_decoder.frames import count_bag_frames
from tactile_sl_decoder.nodes.sensors import decoder_overrides

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from ros_harness import executable, ros_env, stop  # noqa: E402


def _frame_rate(bag: pathlib.Path) -> float:
    """Stereo frames per second of a bag, from its left images' log times."""
    from tactile_sl_common.bag_io import BagReader
    from tactile_sl_decoder.frames import bag_topics

    topic = bag_topics()["left_image"]
    times = [m.log_time_ns for m in BagReader(bag).raw_messages([topic])]
    if len(times) < 2 or times[-1] <= times[0]:
        return 10.0
    return (len(times) - 1) / ((times[-1] - times[0]) * 1e-9)


def _speed_reference(bag: pathlib.Path, repeat: int = 40) -> float:
    """Median ms of threshold + connected components of the bag's first stereo pair."""
    from bench_pipeline import ink_regions

    from tactile_sl_common.images import to_gray
    from tactile_sl_decoder.frames import bag_frames

    frame = next(iter(bag_frames(bag, ground_truth=False, camera_info=False)))
    grays = [to_gray(frame.left_image), to_gray(frame.right_image)]
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for gray in grays:
            ink_regions(gray)
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def main() -> int:  # noqa: C901 - one measurement run: processes, spin loop, report
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bag", type=pathlib.Path, default=REPO / "bags" / "two_contacts.mcap")
    parser.add_argument("--rate", type=float, default=3.0,
                        help="replay rate multiplier of the bag's frame rate (the bundled "
                             "bags are 10 Hz: 3.0 = 30 Hz)")
    parser.add_argument("--loops", type=int, default=43, help="passes over the bag")
    parser.add_argument("--seconds", type=float, default=0.0,
                        help="play this long instead (sets --loops from the bag's frames)")
    parser.add_argument("--sensors", type=int, default=1,
                        help="replay + decoder pairs, each in its own namespace /sensor<i>")
    parser.add_argument("--chain", action="store_true",
                        help="the stage chain instead of one decoder: symbol_extractor and "
                        "symbol_classifier per camera, decoder input:=symbols (5 processes "
                        "per sensor, so the work spreads over the cores)")
    parser.add_argument("--warmup", type=float, default=0.0,
                        help="take the 'start' CPU / memory sample this many seconds after the "
                        "first cloud (memory growth without start-up: allocator pools, the "
                        "touch reference)")
    parser.add_argument("--settle", type=float, default=3.0,
                        help="seconds after the first cloud from which the steady-state "
                             "figures are taken (default 3)")
    parser.add_argument("--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="extra decoder parameter (repeatable), e.g. "
                             "pipeline.threads:=1")
    parser.add_argument("--stage-param", action="append", default=[], metavar="NAME:=VALUE",
                        help="with --chain: extra parameter of every symbol_extractor and "
                             "symbol_classifier (repeatable), e.g. qos.input.depth:=1")
    parser.add_argument("--domain-id", type=int, default=int(os.environ.get("BENCH_DOMAIN_ID", 29)))
    parser.add_argument("--logs", type=pathlib.Path, default=REPO / "out" / "bench_graph")
    args = parser.parse_args()
    if not 1 <= args.sensors <= 8:
        parser.error("--sensors must be 1..8")
    args.logs.mkdir(parents=True, exist_ok=True)
    frames_per_pass = count_bag_frames(args.bag)
    bag_hz = _frame_rate(args.bag)
    if args.seconds > 0:
        args.loops = max(1, math.ceil(args.seconds * bag_hz * args.rate / frames_per_pass))
    expected = frames_per_pass * args.loops
    spaces = ["/tactile"] if args.sensors == 1 else [f"/sensor{i}" for i in range(args.sensors)]
    # what sensors.launch.py gives N decoders on this machine (--param overrides it)
    shared = [] if args.chain else [f"{k}:={str(v).lower()}" for k, v in
                                    decoder_overrides(args.sensors, os.cpu_count()).items()]

    speed_ms = _speed_reference(args.bag)
    context = Context()
    rclpy.init(context=context, domain_id=args.domain_id)
    node = rclpy.create_node("bench_graph", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    latency_ms: dict[str, dict[int, float]] = {ns: {} for ns in spaces}
    wrench_ms: dict[str, dict[int, float]] = {ns: {} for ns in spaces}
    first_stamp: dict[str, int] = {}
    samples: dict[str, dict[str, tuple[float, float, float]]] = {"start": {}, "end": {}}
    procs: dict[str, subprocess.Popen] = {}
    first_cloud: list[float | None] = [None]

    def listener(ns: str, into: dict[str, dict[int, float]]):
        def on_message(msg: PointCloud2 | WrenchStamped) -> None:
            stamp = stamp_to_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)
            into[ns].setdefault(stamp, (time.time_ns() - stamp) / 1e6)
            first_stamp.setdefault(ns, stamp)
            if first_cloud[0] is None:
                first_cloud[0] = time.monotonic()
        return on_message

    reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    for ns in spaces:
        node.create_subscription(PointCloud2, f"{ns}/points", listener(ns, latency_ms), reliable)
        node.create_subscription(WrenchStamped, f"{ns}/wrench", listener(ns, wrench_ms),
                                 reliable)
    env = ros_env(args.domain_id)
    try:
        for ns in spaces:
            tag = ns.strip("/").replace("/", "_")
            decoder_args = ["-r", f"__ns:={ns}", "-p", "publish_symbols:=false"]
            for item in [*shared, *args.param]:
                decoder_args += ["-p", item]
            if args.chain:
                decoder_args += ["-p", "input:=symbols",
                                 "-r", "left/symbols:=left/labelled_symbols",
                                 "-r", "right/symbols:=right/labelled_symbols"]
                stage_params = [a for item in args.stage_param for a in ("-p", item)]
                for side in ("left", "right"):
                    for exe, extra in (("symbol_extractor", ["-r", "image:=image_raw"]),
                                       ("symbol_classifier", [])):
                        extra = [*extra, *stage_params]
                        procs[f"{exe} {ns}/{side}"] = subprocess.Popen(
                            [str(executable("tactile_sl_decoder", exe)), "--ros-args",
                             "-r", f"__ns:={ns}/{side}", *extra],
                            env=env, stdout=open(args.logs / f"{exe}_{tag}_{side}.log", "w"),
                            stderr=subprocess.STDOUT)
            procs[f"decoder {ns}"] = subprocess.Popen(
                [str(executable("tactile_sl_decoder", "decoder")), "--ros-args",
                 *decoder_args],
                env=env, stdout=open(args.logs / f"decoder_{tag}.log", "w"),
                stderr=subprocess.STDOUT)
        # Play only once this listener is matched with every decoder's `points` publisher.
        ready = time.monotonic() + 60
        while (min(node.count_publishers(f"{ns}/points") for ns in spaces) < 1
               and time.monotonic() < ready):
            executor.spin_once(timeout_sec=0.05)
        replays = []
        for ns in spaces:
            tag = ns.strip("/").replace("/", "_")
            replay = subprocess.Popen(
                [str(executable("tactile_sl_camera", "replay")), "--ros-args", "-r",
                 f"__ns:={ns}", "-p", f"bag:={args.bag}", "-p", f"rate:={args.rate}",
                 "-p", "loop:=true", "-p", f"loops:={args.loops}", "-p", "restamp:=true",
                 "-p", "wait_for_subscribers:=1", "-p", "wait_for_subscribers_timeout:=60.0"],
                env=env, stdout=open(args.logs / f"replay_{tag}.log", "w"),
                stderr=subprocess.STDOUT)
            procs[f"replay {ns}"] = replay
            replays.append(replay)
        deadline = time.monotonic() + 60 + expected / (bag_hz * args.rate) * 3
        next_sample = time.monotonic()
        while time.monotonic() < deadline:
            if (not samples["start"] and first_cloud[0] is not None
                    and time.monotonic() >= first_cloud[0] + args.warmup):
                samples["start"] = _sample(procs)
            if time.monotonic() >= next_sample:    # the last sample before the replays end
                samples["end"].update(_sample(procs))
                next_sample += 1.0
            if all(r.poll() is not None for r in replays):
                break
            executor.spin_once(timeout_sec=0.02)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.02)
        samples["end"].update(_sample(procs))
    finally:
        for proc in reversed(list(procs.values())):
            stop(proc)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    what = "extractor -> classifier -> decoder chain" if args.chain else "decoder"
    print(f"replay -> {what} over loopback DDS, {len(spaces)} sensor(s): {expected} stereo "
          f"frames of {args.bag.name} each at {bag_hz * args.rate:.0f} Hz, Fast DDS profile "
          f"{os.environ.get('FASTRTPS_DEFAULT_PROFILES_FILE') or 'none'}, load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    print(f"machine speed before the run: threshold + connected components of the bag's "
          f"first stereo pair, one thread, {speed_ms:.2f} ms (median of 40)")
    if shared or args.param:
        print(f"decoder parameters: {' '.join([*shared, *args.param])}"
              f"{' (the first as sensors.launch.py sets them here)' if shared else ''}")
    received = 0
    for ns in spaces:
        received += len(latency_ms[ns])
        first = first_stamp.get(ns)
        for what, got, reference in (("cloud", latency_ms[ns], 0), ("wrench", wrench_ms[ns], 1)):
            _report(ns, what, got, expected - reference, first, args.settle, latency_ms[ns])
    start, end = samples["start"], samples["end"]
    for name in procs:
        if name in start and name in end:
            (t0, cpu0, rss0), (t1, cpu1, rss1) = start[name], end[name]
            share = 100 * (cpu1 - cpu0) / max(t1 - t0, 1e-9)
            print(f"{name} (with its child processes): CPU {share:.0f} % of one CPU "
                  f"from {args.warmup:g} s after the first cloud on ({t1 - t0:.0f} s); "
                  f"resident memory {rss0:.1f} MB then, {rss1:.1f} MB at the end "
                  f"({rss1 - rss0:+.1f} MB)")
    # Figures, not a verdict: dropped frames are reported above; only a graph that
    # delivered nothing at all (a node that did not start) is an error, so that
    # `make bench` goes on to its other benchmarks on machines that drop frames.
    return 0 if received > 0 else 1


def _report(ns: str, what: str, got: dict[int, float], expected: int, first: int | None,
            settle_s: float, clouds: dict[int, float]) -> None:
    """Drops and latency of one output, over all frames and after ``settle_s`` seconds.

    Steady state: the frames stamped ``settle_s`` after the first stamp; there a wrench is
    missing if a cloud of that stamp came and no wrench.
    """
    lat = np.array(list(got.values()))
    print(f"{ns}: {what} messages received {len(lat)} of {expected}, dropped "
          f"{expected - len(lat)}" +
          (f"; latency image stamp -> {what} received: median {np.median(lat):.1f} ms, p99 "
           f"{np.percentile(lat, 99):.1f} ms, max {lat.max():.1f} ms" if len(lat) else ""))
    if first is None or not len(lat):
        return
    if what == "cloud" and len(got) > 2:
        # where the missing frames were: gaps of more than 1.5 frame periods in the stamps
        stamps = np.array(sorted(got))
        step = np.diff(stamps)
        period = float(np.median(step))
        gaps = np.flatnonzero(step > 1.5 * period)
        if len(gaps):
            where = ", ".join(f"{(stamps[i] - first) / 1e9:.2f} s ({round(step[i] / period) - 1})"
                              for i in gaps[:12])
            print(f"{ns}: frames missing after (missing): {where}"
                  + (f" and {len(gaps) - 12} more gaps" if len(gaps) > 12 else ""))
    cut = first + settle_s * 1e9
    steady = np.array([v for stamp, v in got.items() if stamp >= cut])
    missing = sum(1 for stamp in clouds if stamp >= cut and stamp not in got)
    if len(steady):
        print(f"{ns}: {what} messages from {settle_s:g} s on: {len(steady)}, {missing} "
              f"missing where a cloud came; latency median {np.median(steady):.1f} ms, p90 "
              f"{np.percentile(steady, 90):.1f} ms, p99 {np.percentile(steady, 99):.1f} ms, "
              f"max {steady.max():.1f} ms")


def _proc_stat(pid: int) -> tuple[int, float, float] | None:
    """(parent pid, CPU s, resident MB) of a live process, None once it has gone."""
    try:
        fields = pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        status = pathlib.Path(f"/proc/{pid}/status").read_text()
    except (OSError, IndexError):
        return None
    cpu = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")   # utime + stime
    rss = next((int(line.split()[1]) / 1024.0 for line in status.splitlines()
                if line.startswith("VmRSS:")), float("nan"))   # none once it has exited
    return int(fields[1]), cpu, rss


def _sample(procs: dict[str, subprocess.Popen]) -> dict[str, tuple[float, float, float]]:
    """(wall s, CPU s, resident MB) of every process with its descendants, by name.

    The decoder's camera worker processes (``camera_processes``) count into its figures.
    """
    table = {}
    for entry in pathlib.Path("/proc").iterdir():
        if entry.name.isdigit():
            stat = _proc_stat(int(entry.name))
            if stat is not None:
                table[int(entry.name)] = stat
    children: dict[int, list[int]] = {}
    for pid, (parent, _, _) in table.items():
        children.setdefault(parent, []).append(pid)
    out = {}
    for name, proc in list(procs.items()):
        if proc.pid not in table:
            continue
        cpu = rss = 0.0
        todo = [proc.pid]
        while todo:
            pid = todo.pop()
            cpu += table[pid][1]
            rss += table[pid][2]
            todo.extend(children.get(pid, ()))
        out[name] = (time.monotonic(), cpu, rss)
    return out


if __name__ == "__main__":
    sys.exit(main())
