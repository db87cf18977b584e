"""On a robot, the clouds reach another computer; with the loopback profile they cannot.

Two network namespaces joined only to each other by a veth pair stand for the sensor's
computer (a: `replay` + `decoder`) and another computer of the robot (b: a subscriber),
each with its own /dev/shm (see tests/netns.py). Nothing touches the machine's own
interfaces: the session's leak watch, listening in the root namespace, must still see 0
RTPS packets.

1. config/fastdds_robot.xml with ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET (what
   `TACTILE_SL_NETWORK=robot source env.sh` selects): the clouds arrive in b over the veth
   link, intact (fields, point counts, points equal to the bag's ground truth by row/col
   within 0.1 mm); latency (receive wall time - header stamp of the restamped frames) at
   30 Hz is printed.
   Every cloud that a listener next to the decoder (in a) gets must arrive in b.
2. config/fastdds_loopback.xml, everything else the same: b discovers nothing and receives
   nothing, while the listener in a gets the decoder's clouds.
"""
from __future__ import annotations

import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from netns import NetnsPair, in_netns, netns_pair, unavailable_reason, veth_counters

from tactile_sl_common.bag_io import BagReader

from ros_harness import REPO, executable, ros_env, stop

pytestmark = pytest.mark.ros

BAG = REPO / "bags" / "two_contacts.mcap"      # 7 frames recorded at 10 Hz
LISTENER = pathlib.Path(__file__).with_name("points_listener.py")
LOOPS = 15                                    # 105 frames at 30 Hz: 3.5 s
EXPECTED_FIELDS = [["x", 0, 7, 1], ["y", 4, 7, 1], ["z", 8, 7, 1], ["row", 12, 5, 1],
                   ["col", 16, 5, 1]]         # FLOAT32 = 7, INT32 = 5

# Namespace a: a local listener and the decoder, then (once the test says go) the replay; one
# shell so that all share a's private /dev/shm, as processes on one computer do. The local
# listener tells what the decoder published, whatever the machine's load lets it keep up with.
SENSOR_SCRIPT = r'''
decoder="$1"; replay="$2"; out="$3"; python="$4"; listener="$5"; expect="$6"; shift 6
mkdir -p "$out/a"
"$python" "$listener" --out "$out/a" --seconds 40 --idle 3.0 --expect "$expect" \
  >"$out/listener_a.log" 2>&1 &
"$decoder" --ros-args -r __ns:=/tactile -p publish_symbols:=false >"$out/decoder.log" 2>&1 &
while [ ! -e "$out/go" ]; do sleep 0.05; done
"$replay" --ros-args -r __ns:=/tactile "$@" >"$out/replay.log" 2>&1
echo $? >"$out/replay.rc"
wait
'''


@pytest.fixture
def pair():
    """Two fresh namespaces joined by a veth pair; deleted afterwards, also on failure."""
    reason = unavailable_reason()
    if reason is not None:
        pytest.fail(f"cannot create network namespaces for the robot-network test: {reason}")
    with netns_pair("r") as created:
        yield created


def _env(domain_id: int, profile: str) -> dict[str, str]:
    env = ros_env(domain_id)   # LOCALHOST, overridden below: these processes run in our netns
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(REPO / "config" / profile)
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


def _wait_for(path: pathlib.Path, timeout: float, *alive: subprocess.Popen) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists():
            return True
        if any(p.poll() is not None for p in alive):
            return path.exists()
        time.sleep(0.05)
    return path.exists()


def _logs(out: pathlib.Path) -> str:
    return "\n".join(f"--- {p.name}\n{p.read_text(errors='replace')[-3000:]}"
                     for p in sorted(out.glob("*.log")))


def _load(path: pathlib.Path) -> dict:
    with np.load(path) as npz:
        return {k: npz[k] for k in npz.files}


def run_robot_pair(pair: NetnsPair, out: pathlib.Path, domain_id: int, profile: str,
                   replay_args: list[str], expect: int, remote_discovery: bool) -> dict:
    """Sensor (and a local listener) in namespace a, a listener in b; what both recorded."""
    out.mkdir()
    env = _env(domain_id, profile)
    listener = subprocess.Popen(
        in_netns(pair.ns_b, [sys.executable, str(LISTENER), "--out", str(out),
                             "--seconds", "45", "--idle", "3.0", "--expect", str(expect)]),
        env=env, stdout=open(out / "listener_b.log", "w"), stderr=subprocess.STDOUT)
    sensor = subprocess.Popen(
        in_netns(pair.ns_a, ["sh", "-c", SENSOR_SCRIPT, "sh",
                             str(executable("tactile_sl_decoder", "decoder")),
                             str(executable("tactile_sl_camera", "replay")), str(out),
                             sys.executable, str(LISTENER), str(expect),
                             "-p", f"bag:={BAG}", *replay_args]),
        env=env, stdout=open(out / "sensor.log", "w"), stderr=subprocess.STDOUT,
        start_new_session=True)
    try:
        rx_before = veth_counters(pair.ns_b, pair.veth_b)[0]
        # The decoder's `points` publisher, seen in a; in b too when it should be.
        assert _wait_for(out / "a" / "ready", 30.0, sensor), (
            "the local listener in a never discovered the decoder\n" + _logs(out))
        if remote_discovery:
            assert _wait_for(out / "ready", 30.0, listener, sensor), (
                f"b never discovered a publisher of /tactile/points (listener in b: exit "
                f"{listener.poll()}, sensor shell: exit {sensor.poll()})\n" + _logs(out))
        time.sleep(1.0)   # let the endpoints match each other
        (out / "go").touch()
        assert _wait_for(out / "a" / "clouds.npz", 45.0, sensor), (
            "the local listener in a did not finish\n" + _logs(out))
        _wait_for(out / "replay.rc", 15.0, sensor)
        time.sleep(0.5)
        (out / "stop").touch()   # b: whatever has not arrived by now is not coming
        listener.wait(15)
        rx_after = veth_counters(pair.ns_b, pair.veth_b)[0]
    finally:
        stop(listener)
        if sensor.poll() is None:
            os.killpg(sensor.pid, signal.SIGTERM)   # the shell and the nodes of this run
            try:
                sensor.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(sensor.pid, signal.SIGKILL)
                sensor.wait()
    assert (out / "clouds.npz").exists(), "the listener in b wrote no result\n" + _logs(out)
    result = _load(out / "clouds.npz")
    result["local"] = _load(out / "a" / "clouds.npz")
    result["veth_rx_bytes"] = rx_after - rx_before
    rc = out / "replay.rc"
    result["replay_rc"] = int(rc.read_text()) if rc.exists() else None
    return result


def ground_truth_grid() -> np.ndarray:
    """(frames, rows, cols, 3) true cell centres of the bag, NaN where a cell has none."""
    frames = []
    for _, msg in BagReader(BAG).messages(["/tactile/ground_truth/points"]):
        frames.append(structured(bytes(msg.data), msg.point_step))
    rows = max(int(f["row"].max()) for f in frames) + 1
    cols = max(int(f["col"].max()) for f in frames) + 1
    grid = np.full((len(frames), rows, cols, 3), np.nan)
    for i, f in enumerate(frames):
        grid[i, f["row"], f["col"]] = np.stack([f["x"], f["y"], f["z"]], axis=1)
    return grid


def structured(data: bytes, point_step: int) -> np.ndarray:
    dtype = np.dtype({"names": ["x", "y", "z", "row", "col"],
                      "formats": ["<f4", "<f4", "<f4", "<i4", "<i4"],
                      "offsets": [0, 4, 8, 12, 16], "itemsize": point_step})
    return np.frombuffer(data, dtype)


def check_intact(result: dict) -> tuple[int, float]:
    """Every cloud: the contract's fields, and points equal to one ground-truth frame."""
    truth = ground_truth_grid()
    matched = set()
    worst = 0.0
    offset = 0
    for i, (fields, step, count) in enumerate(zip(result["fields"], result["point_step"],
                                                  result["points"])):
        assert json.loads(str(fields)) == EXPECTED_FIELDS, f"cloud {i}: fields {fields}"
        assert str(result["frame_id"][i]) == "tactile_left_optical_frame"
        size = int(step) * int(count)
        points = structured(result["data"][offset:offset + size].tobytes(), int(step))
        offset += size
        assert count > 0, f"cloud {i} is empty"
        assert (points["row"] >= 0).all() and (points["row"] < truth.shape[1]).all()
        assert (points["col"] >= 0).all() and (points["col"] < truth.shape[2]).all()
        xyz = np.stack([points["x"], points["y"], points["z"]], axis=1).astype(np.float64)
        errors = np.linalg.norm(truth[:, points["row"], points["col"]] - xyz, axis=2)
        per_frame = np.where(np.isnan(errors).any(axis=1), np.inf, errors.max(axis=1))
        best = int(np.argmin(per_frame))
        assert per_frame[best] < 1e-4, (
            f"cloud {i}: {count} points, no ground-truth frame within 0.1 mm "
            f"(best: frame {best}, {per_frame[best] * 1e3:.3f} mm)")
        matched.add(best)
        worst = max(worst, float(per_frame[best]))
    assert offset == result["data"].size
    return len(matched), worst


def test_clouds_reach_another_computer_only_with_the_robot_profile(pair, domain_id, tmp_path,
                                                                   dds_sniffer):
    frames = 7 * LOOPS
    replay_30hz = ["-p", "rate:=3.0", "-p", "restamp:=true", "-p", "loop:=true",
                   "-p", f"loops:={LOOPS}", "-p", "wait_for_subscribers:=1",
                   "-p", "wait_for_subscribers_timeout:=30.0"]
    t0 = time.monotonic()
    robot = run_robot_pair(pair, tmp_path / "robot", domain_id, "fastdds_robot.xml",
                           replay_30hz, frames, remote_discovery=True)
    t_robot = time.monotonic() - t0
    logs = _logs(tmp_path / "robot")
    assert robot["replay_rc"] == 0, logs
    assert "XMLPARSER" not in logs, "Fast DDS rejected config/fastdds_robot.xml\n" + logs
    received = len(robot["recv_ns"])
    published = len(robot["local"]["recv_ns"])
    assert received > 0, "no cloud crossed the veth link\n" + logs
    frames_matched, worst = check_intact(robot)
    latency_ms = (robot["recv_ns"] - robot["stamp_ns"]) / 1e6
    cloud_bytes = int((robot["point_step"] * robot["points"]).sum())
    print(f"\nrobot profile, SUBNET discovery, {pair.ns_a} -> {pair.ns_b} over veth "
          f"{pair.addr_a} -> {pair.addr_b}: {received} clouds received in b of {published} "
          f"published by the decoder in a ({frames} frames played at 30 Hz), all intact "
          f"({frames_matched}/7 bag frames seen, max error vs ground truth "
          f"{worst * 1e3:.4f} mm); latency stamp -> received in b: median "
          f"{np.median(latency_ms):.1f} ms, p99 {np.percentile(latency_ms, 99):.1f} ms, "
          f"max {latency_ms.max():.1f} ms; veth into b: {robot['veth_rx_bytes']} bytes for "
          f"{cloud_bytes} bytes of cloud data; {t_robot:.1f} s")
    # Every cloud the listener next to the decoder saw also crossed the link (that listener
    # may itself join late or lose a reliable sample on a loaded machine, so b may hold more).
    missing = set(robot["local"]["stamp_ns"].tolist()) - set(robot["stamp_ns"].tolist())
    assert not missing, (f"{len(missing)} of the {published} clouds seen in a never reached "
                         f"b ({received} did)\n" + logs)
    assert received >= 5, f"only {received} clouds crossed the veth link\n" + logs
    # Over the link, not through shared memory (each namespace has its own /dev/shm).
    assert robot["veth_rx_bytes"] >= cloud_bytes
    # How many of the 30 Hz frames the decoder keeps up with depends on the machine's load
    # (on 2 busy cores: 20 to 60 of 105), not on the network: not a criterion here. (The
    # listeners give up 3 s after the last cloud; while the decoder still prepared its touch
    # reference in line, 1-2.5 s after its first cloud, a 2 s wait once ended after 1 cloud.)

    t0 = time.monotonic()
    loopback = run_robot_pair(pair, tmp_path / "loopback", domain_id, "fastdds_loopback.xml",
                              replay_30hz, frames, remote_discovery=False)
    logs = _logs(tmp_path / "loopback")
    published = len(loopback["local"]["recv_ns"])
    print(f"loopback profile, otherwise the same: {len(loopback['recv_ns'])} clouds and "
          f"{int(loopback['publishers_seen'])} publishers seen in b while the decoder in a "
          f"published {published}; veth into b: {loopback['veth_rx_bytes']} bytes; "
          f"{time.monotonic() - t0:.1f} s")
    assert loopback["replay_rc"] == 0, logs
    assert "XMLPARSER" not in logs, "Fast DDS rejected config/fastdds_loopback.xml\n" + logs
    assert published >= 1, "the decoder published nothing in a\n" + logs
    assert len(loopback["recv_ns"]) == 0
    assert int(loopback["publishers_seen"]) == 0
    # Inside the namespaces, invisible to the leak watch in the root namespace.
    assert dds_sniffer.leaks == []
