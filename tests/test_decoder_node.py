"""The installed `decoder` node over loopback DDS: bad input is survived, replay == node.

The node runs as its own process (installed executable), on a ROS domain of its own, with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST; the test publishes stereo frames from a bundled bag
and listens for point clouds.
"""
import pathlib
import time

import numpy as np
import pytest

from ros_harness import BAGS

BAG = BAGS / "sphere_deep_small.mcap"

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def _bag_messages(limit_frames=2):
    """(kind, side, rclpy message) of the first frames of the bundled bag, in bag order."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CameraInfo, Image

    from tactile_sl_common.bag_io import BagReader

    out, stamps = [], []
    for raw in BagReader(BAG).raw_messages():
        side = "left" if "/left/" in raw.topic else "right"
        if raw.topic.endswith("image_raw"):
            msg = deserialize_message(raw.data, Image)
            kind = "image"
        elif raw.topic.endswith("camera_info"):
            msg = deserialize_message(raw.data, CameraInfo)
            kind = "info"
        else:
            continue
        t = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if t not in stamps:
            stamps.append(t)
        if len(stamps) > limit_frames:
            break
        out.append((kind, side, msg))
    return out


def _io(ros):
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import CameraInfo, Image, PointCloud2

    pubs = {}
    for side in ("left", "right"):
        pubs[("image", side)] = ros.node.create_publisher(Image, f"/tactile/{side}/image_raw",
                                                          qos_profile_sensor_data)
        pubs[("info", side)] = ros.node.create_publisher(
            CameraInfo, f"/tactile/{side}/camera_info", qos_profile_sensor_data)
    clouds = []
    ros.node.create_subscription(PointCloud2, "/tactile/points", clouds.append, 10)
    return pubs, clouds


def _wait_matched(ros, pubs, timeout=40.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if all(p.get_subscription_count() > 0 for p in pubs.values()):
            ros.spin(1.0)    # let the other side of the discovery settle too
            return
        ros.spin(0.05)
    pytest.fail("decoder did not subscribe in time")


def _send_until_cloud(ros, clouds, stamp, publish, attempts=5, wait=5.0):
    """Publish one frame (again, if best-effort delivery lost it) until its cloud arrives."""
    for _ in range(attempts):
        publish()
        end = time.monotonic() + wait
        while time.monotonic() < end:
            if any((c.header.stamp.sec, c.header.stamp.nanosec) == stamp for c in clouds):
                return True
            ros.spin(0.05)
    return False


def _stamped(msg, sec, nanosec):
    import copy

    m = copy.deepcopy(msg)
    m.header.stamp.sec, m.header.stamp.nanosec = sec, nanosec
    return m


def test_bad_input_is_warned_skipped_and_survived(ros):
    from sensor_msgs.msg import Image

    proc = ros.start()
    pubs, clouds = _io(ros)
    _wait_matched(ros, pubs)
    msgs = _bag_messages(1)
    img = {s: m for k, s, m in msgs if k == "image"}
    info = {s: m for k, s, m in msgs if k == "info"}
    clock = [100]

    def expect(text, make_left=None, make_right=None, sync=True):
        """Send fresh bad frames (best effort may lose one) until the warning shows."""
        for _ in range(5):
            clock[0] += 1
            sec = clock[0]
            left = make_left(sec) if make_left else _stamped(img["left"], sec, 0)
            right = make_right(sec) if make_right else _stamped(img["right"], sec, 0)
            pubs[("image", "left")].publish(left)
            ros.spin(0.05)
            pubs[("image", "right")].publish(right)
            if not sync:      # a later good pair pushes the unpaired ones out
                ros.spin(0.05)
                clock[0] += 1
                pubs[("image", "left")].publish(_stamped(img["left"], clock[0], 0))
                pubs[("image", "right")].publish(_stamped(img["right"], clock[0], 0))
            if proc.wait_for_log(text, 4.0, ros.spin_once):
                return
        pytest.fail(f"no warning {text!r}: {proc.lines()[-6:]}")

    def good_cloud():
        clock[0] += 1
        stamp = (clock[0], 345)

        def publish():
            for side in ("left", "right"):
                pubs[("info", side)].publish(info[side])
            ros.spin(0.2)
            pubs[("image", "left")].publish(_stamped(img["left"], *stamp))
            pubs[("image", "right")].publish(_stamped(img["right"], *stamp))
        assert _send_until_cloud(ros, clouds, stamp, publish), proc.log()
        cloud = [c for c in clouds if (c.header.stamp.sec, c.header.stamp.nanosec) == stamp]
        assert cloud[0].width > 500 and cloud[0].is_dense and cloud[0].height == 1

    # 1. no CameraInfo yet
    expect("no CameraInfo received yet")
    # 2. degenerate CameraInfo (all-zero K, as an uncalibrated driver sends)
    for side in ("left", "right"):
        bad = _stamped(info[side], 1, 0)
        bad.k = np.zeros(9)
        pubs[("info", side)].publish(bad)
    ros.spin(0.3)
    expect("not calibrated")
    # 3. good CameraInfo and a good frame: a cloud, stamped exactly
    for side in ("left", "right"):
        pubs[("info", side)].publish(info[side])
    ros.spin(0.3)
    good_cloud()

    # 4. wrong encoding
    def wrong_encoding(sec):
        m = _stamped(img["left"], sec, 0)
        m.encoding = "16UC1"
        return m
    expect("unsupported image encoding", wrong_encoding)

    # 5. image size differs from its CameraInfo
    def small(sec):
        m = Image()
        m.header.stamp.sec = sec
        m.height, m.width, m.encoding, m.step = 240, 320, "mono8", 320
        m.data = bytes(320 * 240)
        return m
    expect("320x240", small)

    # 6. empty image
    def empty(sec):
        m = Image()
        m.header.stamp.sec = sec
        m.encoding = "mono8"
        return m
    expect("empty image", empty)
    # 7. unsynchronised stereo: stamps that never match
    expect("no stereo partner", make_right=lambda sec: _stamped(img["right"], sec, 5 * 10**8),
           sync=False)
    # still alive and still decoding
    good_cloud()
    assert proc.process.poll() is None


def test_replay_offline_equals_points_through_the_node(ros, tmp_path):
    """`tactile-sl replay` on a bag and the node fed the same frames give identical clouds;
    the node's symbols_decoded carry the in-process pipeline's glyphs, labels and cells."""
    from tactile_sl_common.bag_io import BagReader
    from tactile_sl_common.images import to_gray
    from tactile_sl_decoder.cli import main as cli_main
    from tactile_sl_decoder.pipeline import PatternSpec, StereoPipeline
    from tactile_sl_decoder.symbol_array import from_message
    from tactile_sl_msgs.msg import SymbolArray

    out = tmp_path / "out.mcap"
    assert cli_main(["replay", str(BAG), "-o", str(out), "--no-progress"]) == 0
    offline = {}
    for _raw, msg in BagReader(out).messages(["/tactile/points"]):
        offline[(msg.header.stamp.sec, msg.header.stamp.nanosec)] = bytes(msg.data)
    assert len(offline) >= 3

    proc = ros.start()
    pubs, clouds = _io(ros)
    symbols = {"left": {}, "right": {}}    # symbols_decoded: built only while subscribed
    subs = [ros.node.create_subscription(
        SymbolArray, f"/tactile/{side}/symbols_decoded",
        lambda m, side=side: symbols[side].__setitem__(
            (m.header.stamp.sec, m.header.stamp.nanosec), m), 10) for side in symbols]
    _wait_matched(ros, pubs)
    end = time.monotonic() + 20.0
    while not all(sub.get_publisher_count() for sub in subs) and time.monotonic() < end:
        ros.spin(0.05)
    ros.spin(0.5)     # the decoder's side of the match
    msgs = _bag_messages(3)
    frames = {}
    for kind, side, m in msgs:
        frames.setdefault((m.header.stamp.sec, m.header.stamp.nanosec), []).append((kind, side, m))
    for stamp, parts in sorted(frames.items()):
        def publish(parts=parts):
            for kind, side, m in sorted(parts, key=lambda p: p[0] != "info"):   # info first
                pubs[(kind, side)].publish(m)
                ros.spin(0.2 if kind == "info" else 0.02)
        _send_until_cloud(ros, clouds, stamp, publish)
    online = {(c.header.stamp.sec, c.header.stamp.nanosec): bytes(c.data) for c in clouds}
    assert set(online) == set(frames), proc.lines()[-5:]
    for stamp in online:
        assert online[stamp] == offline[stamp]
    # the decoded glyphs of both images, as the same pipeline gives them in process
    ros.spin(0.5)
    pipe = StereoPipeline(PatternSpec.load())
    for stamp, parts in sorted(frames.items()):
        part = {(kind, side): m for kind, side, m in parts}
        res = pipe.process(to_gray(part[("image", "left")]), to_gray(part[("image", "right")]),
                           part[("info", "left")], part[("info", "right")])
        for side, want in (("left", res.left), ("right", res.right)):
            assert stamp in symbols[side], f"no {side}/symbols_decoded for {stamp}"
            got = from_message(symbols[side][stamp])
            assert len(got) == len(want) > 100
            for key in ("u", "v", "label", "row", "col"):
                assert np.array_equal(getattr(got, key), getattr(want, key)), (side, key)
    # classification runs on numpy: torch (~3.5 s of CPU and ~190 MB at start) is not loaded
    maps = pathlib.Path(f"/proc/{proc.process.pid}/maps").read_text()
    assert "libtorch" not in maps and "libc10" not in maps


def test_symbols_input_gives_the_same_points_as_images(ros, tmp_path):
    """Chained stages: decoder fed labelled SymbolArrays == decoder fed images (replay)."""
    from rclpy.qos import qos_profile_sensor_data

    from tactile_sl_common.bag_io import BagReader
    from tactile_sl_common.images import to_gray
    from tactile_sl_decoder.cli import main as cli_main
    from tactile_sl_decoder.nodes.decoder_node import make_symbol_array
    from tactile_sl_decoder.pipeline import PatternSpec, StereoPipeline
    from tactile_sl_msgs.msg import SymbolArray

    out = tmp_path / "out.mcap"
    assert cli_main(["replay", str(BAG), "-o", str(out), "--no-progress"]) == 0
    offline = {(m.header.stamp.sec, m.header.stamp.nanosec): bytes(m.data)
               for _, m in BagReader(out).messages(["/tactile/points"])}

    proc = ros.start("-p", "input:=symbols")
    pubs, clouds = _io(ros)
    for side in ("left", "right"):
        pubs[("symbols", side)] = ros.node.create_publisher(
            SymbolArray, f"/tactile/{side}/symbols", qos_profile_sensor_data)
    del pubs[("image", "left")], pubs[("image", "right")]
    _wait_matched(ros, pubs)
    stages = StereoPipeline(PatternSpec.load())     # the stage nodes' work, in-process
    frames = {}
    for kind, side, m in _bag_messages(2):
        frames.setdefault((m.header.stamp.sec, m.header.stamp.nanosec), {})[(kind, side)] = m
    for stamp, parts in sorted(frames.items()):
        left, right = stages.extract_pair(to_gray(parts[("image", "left")]),
                                          to_gray(parts[("image", "right")]))
        stages.classify_pair(left, right)
        def publish(parts=parts, left=left, right=right):
            for side in ("left", "right"):
                pubs[("info", side)].publish(parts[("info", side)])
            ros.spin(0.3)
            for side, g in (("left", left), ("right", right)):
                pubs[("symbols", side)].publish(
                    make_symbol_array(g, parts[("image", side)].header))
                ros.spin(0.02)
        _send_until_cloud(ros, clouds, stamp, publish)
    online = {(c.header.stamp.sec, c.header.stamp.nanosec): bytes(c.data) for c in clouds}
    assert set(online) == set(frames), proc.lines()[-5:]
    for stamp in online:
        assert online[stamp] == offline[stamp]


def test_images_before_camera_info_still_give_a_cloud(ros):
    """Messages of one frame may arrive in any order (contract): the first frame's images
    overtaking its CameraInfo must not cost the frame."""
    ros.start()
    pubs, clouds = _io(ros)
    _wait_matched(ros, pubs)
    msgs = _bag_messages(1)
    img = {s: m for k, s, m in msgs if k == "image"}
    info = {s: m for k, s, m in msgs if k == "info"}
    stamp = (img["left"].header.stamp.sec, img["left"].header.stamp.nanosec)
    for side in ("left", "right"):
        pubs[("image", side)].publish(img[side])
    ros.spin(0.3)
    assert not clouds, "a cloud before any CameraInfo"
    for side in ("left", "right"):
        pubs[("info", side)].publish(info[side])
    end = time.monotonic() + 10.0
    while time.monotonic() < end and not clouds:
        ros.spin(0.05)
    assert [(c.header.stamp.sec, c.header.stamp.nanosec) for c in clouds] == [stamp]
    assert clouds[0].width > 500
