"""The viewer costs the decoder nothing: its frame rate with a page open, stalled, and without.

`replay` -> `decoder` at a fixed input rate (default 30 Hz, two_contacts.mcap looping,
restamped), as `bench_graph.py` runs them; this script listens to `points` and measures in
phases of ``--seconds`` each (after ``--settle`` seconds):

1. no viewer at all;
2. the `viewer` node and headless Chromium (the distribution's, via playwright) with the page
   open, drawing every frame it is sent, at the viewer's default cap (``max_rate``, 10 frames
   a second to each page; ``--max-rate`` sets another);
   2b. the same page with the cap off (``max_rate`` 0, set live): every frame it can draw;
   2c. instead of the browser, a client that asks for every frame and reads it without
   drawing, cap off (the viewer's own cost at full rate: conversion, encoding);
3. the page closed; two stalled clients on the viewer for ``--stall`` seconds: one that
   connects and never asks for a frame (a frozen tab), one that asks for frames and never
   reads its socket (its receive window fills); the viewer's resident memory is sampled
   every second;
4. the viewer still running with no page (it unsubscribes ``linger`` seconds after the last
   one).

Printed per phase: decoded frames per second (clouds received here whose stamps fall in the
phase, so a late cloud counts for its own frame), against the mean of phases 1 and 4 (without
a page, before and after); stamp-to-cloud latency (median, p90); CPU of the decoder (with
its camera worker processes), the viewer and Chromium (per cent of one CPU); the one-minute
load average at the phase's end; frames the page drew; the viewer's memory over the stall.
Chromium runs at nice 19 by default (``--browser-nice``): on a robot the page is open on
another computer; here it shares the cores. Figures, not a pass/fail test.

    python tools/bench_viewer.py                       # 30 Hz, 20 s phases, 30 s stall
    python tools/bench_viewer.py --rate 6 --seconds 30 # 60 Hz
"""
from __future__ import annotations

import argparse
import base64
import os
import pathlib
import re
import socket
import struct
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np
import rclpy
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from bench_graph import _frame_rate  # noqa: E402

from ros_harness import browser_page, executable, ros_env, stop  # noqa: E402


class Clouds:
    """Arrival time and stamp-to-arrival latency of every cloud (this process)."""

    def __init__(self, domain_id: int) -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node("bench_viewer", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.arrivals: list[tuple[int, float]] = []      # (stamp ns, latency ms)
        self.node.create_subscription(PointCloud2, "/tactile/points", self._on_cloud,
                                      QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))

    def _on_cloud(self, msg: PointCloud2) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.arrivals.append((stamp, (time.time_ns() - stamp) / 1e6))

    def spin(self, seconds: float, also: Any = None) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)
            if also is not None:
                also()

    def set_double(self, node: str, name: str, value: float) -> None:
        """Set a double parameter of ``node`` (a live change, as `ros2 param set`)."""
        client = self.node.create_client(SetParameters, f"{node}/set_parameters")
        try:
            if not client.wait_for_service(timeout_sec=10.0):
                raise RuntimeError(f"{node}/set_parameters did not appear")
            value_msg = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value)
            future = client.call_async(SetParameters.Request(
                parameters=[Parameter(name=name, value=value_msg)]))
            self.executor.spin_until_future_complete(future, timeout_sec=10.0)
            result = future.result()
            if result is None or not result.results[0].successful:
                raise RuntimeError(f"{node}: {name} := {value} refused: {result}")
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def _cpu_of(pids: list[int]) -> float:
    """CPU seconds (user + system) of these processes, 0 for those gone."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0.0
    for pid in pids:
        try:
            fields = pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick
        except (OSError, IndexError, ValueError):
            pass
    return total


def _pids_with(text: str) -> list[int]:
    """Processes whose command line contains ``text`` (Chromium's, by its profile folder)."""
    found = []
    for entry in pathlib.Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if text in (entry / "cmdline").read_bytes().decode(errors="replace"):
                    found.append(int(entry.name))
            except OSError:
                pass
    return found


def _descendants(roots: list[int]) -> list[int]:
    """``roots`` and every process below them (Chromium's renderers, GPU and zygote)."""
    children: dict[int, list[int]] = {}
    for entry in pathlib.Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    found, todo = [], list(roots)
    while todo:
        pid = todo.pop()
        found.append(pid)
        todo += children.get(pid, [])
    return found


def _renice(pids: list[int], niceness: int) -> None:
    """Every thread of these processes (on Linux a niceness belongs to a thread)."""
    for pid in pids:
        try:
            tids = [int(t.name) for t in pathlib.Path(f"/proc/{pid}/task").iterdir()]
        except OSError:
            continue
        for tid in tids:
            try:
                os.setpriority(os.PRIO_PROCESS, tid, niceness)
            except OSError:
                pass


def _rss_mb(pid: int) -> float:
    for line in pathlib.Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _ws_frame(text: str) -> bytes:
    """One masked WebSocket text frame (RFC 6455 5.2/5.3; clients must mask)."""
    payload = text.encode()
    mask = os.urandom(4)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    return struct.pack("!BB", 0x81, 0x80 | len(payload)) + mask + masked


def stalled_client(port: int, ask: bool) -> socket.socket:
    """A WebSocket client that never reads past the handshake (small receive window)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                  f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                  f"Sec-WebSocket-Version: 13\r\n\r\n").encode())
    reply = b""
    while b"\r\n\r\n" not in reply:
        chunk = sock.recv(1)
        if not chunk:
            raise ConnectionError("the viewer closed the connection during the handshake")
        reply += chunk
    if b" 101 " not in reply.split(b"\r\n", 1)[0]:
        raise ConnectionError(f"no WebSocket: {reply[:80]!r}")
    if ask:
        sock.sendall(_ws_frame('{"type":"next","map":"pressure"}'))
    sock.setblocking(False)
    return sock


def _keep_asking(sock: socket.socket) -> bool:
    """Ask for the next frame again (never reading); False once the viewer closed it."""
    try:
        sock.send(_ws_frame('{"type":"next","map":"pressure"}'))
        return True
    except (BlockingIOError, InterruptedError):
        return True
    except OSError:
        return False


class ReadingClient:
    """A page without a browser: asks for every frame and reads it, draws nothing (aiohttp)."""

    def __init__(self, url: str) -> None:
        import asyncio
        import threading

        self.frames = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=lambda: asyncio.run(self._run(url)), daemon=True)
        self._thread.start()

    async def _run(self, url: str) -> None:
        import aiohttp

        async with aiohttp.ClientSession() as http:
            async with http.ws_connect(url + "ws") as ws:
                await ws.receive()                            # hello
                while not self._stop.is_set():
                    await ws.send_str('{"type":"next","map":"pressure"}')
                    msg = await ws.receive()
                    if msg.type != aiohttp.WSMsgType.BINARY:
                        break
                    self.frames += 1

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)


def main() -> int:  # noqa: C901 - one measurement run: processes, phases, report
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bag", type=pathlib.Path, default=REPO / "bags" / "two_contacts.mcap")
    parser.add_argument("--rate", type=float, default=3.0,
                        help="replay rate multiplier (the bundled bags are 10 Hz: 3 = 30 Hz)")
    parser.add_argument("--seconds", type=float, default=20.0, help="length of each phase")
    parser.add_argument("--settle", type=float, default=4.0,
                        help="seconds before each phase's measurement")
    parser.add_argument("--stall", type=float, default=30.0, help="length of the stall phase")
    parser.add_argument("--browser-nice", type=int, default=19,
                        help="niceness of Chromium's processes (default 19: the browser "
                        "normally runs on another computer; 0 = as any process)")
    parser.add_argument("--max-rate", type=float, default=None,
                        help="the viewer's max_rate in phase 2 (default: the node's own, 10)")
    parser.add_argument("--page-fps", type=float, default=0.0,
                        help="the page asks for at most this many frames a second (its ?fps= "
                        "option; 0 = every frame it can draw)")
    parser.add_argument("--domain-id", type=int,
                        default=int(os.environ.get("BENCH_DOMAIN_ID", 29)))
    parser.add_argument("--logs", type=pathlib.Path, default=REPO / "out" / "bench_viewer")
    args = parser.parse_args()
    args.logs.mkdir(parents=True, exist_ok=True)
    env = ros_env(args.domain_id)
    clouds = Clouds(args.domain_id)
    procs: dict[str, subprocess.Popen] = {}
    rows: list[tuple[str, dict]] = []

    def launch(name: str, package: str, exe: str, ros_args: list[str]) -> subprocess.Popen:
        procs[name] = subprocess.Popen(
            [str(executable(package, exe)), "--ros-args", "-r", "__ns:=/tactile", *ros_args],
            env=env, stdout=open(args.logs / f"{name}.log", "w"), stderr=subprocess.STDOUT)
        return procs[name]

    def measure(name: str, extra_pids: list[int] | None = None, during: Any = None,
                seconds: float | None = None) -> dict:
        """CPU over the phase now; frames by stamp window at the end (late clouds count)."""
        clouds.spin(args.settle, during)
        # the decoder with its camera workers (child processes)
        watched = {k: _descendants([p.pid]) for k, p in procs.items() if k != "replay"}
        if extra_pids:
            watched["chromium"] = extra_pids
        cpu0 = {k: _cpu_of(v) for k, v in watched.items()}
        t0, w0 = time.monotonic(), time.time_ns()
        clouds.spin(seconds or args.seconds, during)
        t1, w1 = time.monotonic(), time.time_ns()
        row = {"window": (w0, w1), "load": os.getloadavg()[0],
               "cpu": {k: 100 * (_cpu_of(v) - cpu0[k]) / (t1 - t0) for k, v in watched.items()}}
        rows.append((name, row))
        return row

    try:
        launch("decoder", "tactile_sl_decoder", "decoder", [])
        deadline = time.monotonic() + 60
        while clouds.node.count_publishers("/tactile/points") < 1 and time.monotonic() < deadline:
            clouds.spin(0.05)
        launch("replay", "tactile_sl_camera", "replay", [
            "-p", f"bag:={args.bag}", "-p", f"rate:={args.rate}", "-p", "loop:=true",
            "-p", "restamp:=true", "-p", "wait_for_subscribers:=1",
            "-p", "wait_for_subscribers_timeout:=60.0"])
        measure("1 no viewer")
        cap = [] if args.max_rate is None else ["-p", f"max_rate:={float(args.max_rate)}"]
        viewer = launch("viewer", "tactile_sl_viewer", "viewer", ["-p", "port:=0",
                                                                  "-p", "linger:=2.0", *cap])
        log = args.logs / "viewer.log"
        url = ""
        deadline = time.monotonic() + 30
        while not url and time.monotonic() < deadline and viewer.poll() is None:
            clouds.spin(0.1)
            found = re.search(r"viewer: open (http://\S+/)", log.read_text(errors="replace"))
            url = found.group(1) if found else ""
        if not url:
            print(f"bench_viewer: the viewer did not start; see {log}")
            return 1
        port = int(url.rstrip("/").rsplit(":", 1)[1])
        with tempfile.TemporaryDirectory() as profile, browser_page(pathlib.Path(profile)) as page:
            browser = [p for p in _pids_with(profile)
                       if b"--type=" not in pathlib.Path(f"/proc/{p}/cmdline").read_bytes()]
            page.goto(url + (f"?fps={args.page_fps:g}" if args.page_fps > 0 else ""))
            clouds.spin(1.0)
            chromium = _descendants(browser)
            _renice(chromium, args.browser_nice)    # the browser stands for a laptop's

            def drawn() -> int:
                return int(page.evaluate("Number(document.body.dataset.frames)"))

            shown = drawn()
            cap_text = "10" if args.max_rate is None else f"{args.max_rate:g}"
            row = measure(f"2 page, cap {cap_text}/s", chromium)
            row["page_fps"] = (drawn() - shown) / (args.seconds + args.settle)
            clouds.set_double("/tactile/viewer", "max_rate", 0.0)
            shown = drawn()
            row = measure("2b page, no cap", chromium)
            row["page_fps"] = (drawn() - shown) / (args.seconds + args.settle)
        reader = ReadingClient(url)
        row = measure("2c reading client")
        reader.close()
        row["page_fps"] = reader.frames / (args.seconds + args.settle)
        frozen = stalled_client(port, ask=False)
        reader_stalled = stalled_client(port, ask=True)
        rss: list[tuple[float, float]] = []
        open_until: list[float] = []

        def during_stall() -> None:
            now = time.monotonic()
            if not rss or now - rss[-1][0] >= 1.0:
                rss.append((now, _rss_mb(viewer.pid)))
            if not open_until and not _keep_asking(reader_stalled):
                open_until.append(now)

        stall_start = time.monotonic()
        row = measure("3 stalled clients", during=during_stall,
                      seconds=max(1.0, args.stall - args.settle))
        mem = [m for _, m in rss]
        row["rss"] = (mem[0], max(mem), mem[-1]) if mem else None
        row["closed_after"] = (open_until[0] - stall_start) if open_until else None
        frozen.close()
        reader_stalled.close()
        measure("4 viewer, no page")
        clouds.spin(1.0)                                 # the last clouds of the window
    finally:
        for proc in reversed(list(procs.values())):
            stop(proc)
        clouds.close()
    print(f"viewer benchmark: replay -> decoder at {_frame_rate(args.bag) * args.rate:.0f} Hz "
          f"nominal ({args.bag.name}, looping), phases of {args.seconds:g} s after "
          f"{args.settle:g} s, stall {args.stall:g} s, Chromium at nice {args.browser_nice}; "
          f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs now (per phase: "
          f"at its end); CPU in % of one CPU, the decoder's with its camera workers")
    for _, row in rows:
        w0, w1 = row["window"]
        lat = np.array([ms for stamp, ms in clouds.arrivals if w0 <= stamp < w1] or [np.nan])
        row.update(fps=np.isfinite(lat).sum() / ((w1 - w0) * 1e-9),
                   lat50=float(np.median(lat)), lat90=float(np.percentile(lat, 90)))
    base = (rows[0][1]["fps"] + rows[-1][1]["fps"]) / 2     # without a page: before and after
    print(f"without a page (mean of phases 1 and 4): {base:.1f} frames/s decoded; frames "
          f"counted by stamp within each phase")
    for name, row in rows:
        cpu = ", ".join(f"{k} {v:.0f} %" for k, v in row["cpu"].items())
        change = 100 * (row["fps"] - base) / base if base else float("nan")
        print(f"{name:<20} decoded {row['fps']:5.1f} frames/s ({change:+5.1f} %); "
              f"latency median {row['lat50']:.1f} ms, p90 {row['lat90']:.1f} ms; load "
              f"{row['load']:.2f}; CPU: {cpu}")
        if "page_fps" in row:
            print(f"{'':<20} the page got {row['page_fps']:.1f} frames/s")
        if row.get("rss"):
            first, peak, last = row["rss"]
            closed = (f"; the viewer closed the non-reading client after "
                      f"{row['closed_after']:.0f} s" if row.get("closed_after") else
                      "; the non-reading client stayed connected")
            print(f"{'':<20} viewer resident memory over the stall: {first:.1f} MB at the "
                  f"start, peak {peak:.1f} MB, {last:.1f} MB at the end{closed}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
