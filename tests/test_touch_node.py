"""The decoder node's touch outputs over DDS equal `tactile-sl replay`'s, field for field.

Field, wrench, contact, depth and slip: one per frame after the reference, stamped like it.

(Every field and array compares equal, so the payload bytes are the same; the CDR padding
bytes are not compared: Fast CDR leaves them unset.)

Also: nothing is published before the reference (said once), ``tare`` is refused while the
pad is pressed, and a bad sensor file stops the node with one FATAL line.
"""
import math
import time

import pytest
from test_decoder_node import BAG, _bag_messages, _io, _send_until_cloud, _wait_matched

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TOUCH_TOPICS = ("field", "wrench", "contact", "depth", "slip")


def _offline(tmp_path, bag=BAG):
    from tactile_sl_common.bag_io import BagReader
    from tactile_sl_decoder.cli import main as cli_main

    out = tmp_path / "out.mcap"
    assert cli_main(["replay", str(bag), "-o", str(out), "--no-progress"]) == 0
    offline: dict[str, dict] = {t: {} for t in TOUCH_TOPICS}
    reader = BagReader(out)
    for raw in reader.raw_messages([f"/tactile/{t}" for t in TOUCH_TOPICS]):
        topic = raw.topic.rsplit("/", 1)[1]
        offline[topic][raw.log_time_ns] = bytes(raw.data)
    return offline


def test_touch_outputs_equal_offline_replay_and_tare_is_refused_when_pressed(ros, tmp_path):
    from geometry_msgs.msg import WrenchStamped
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import Image, PointCloud2
    from std_srvs.srv import Trigger
    from visualization_msgs.msg import Marker, MarkerArray

    from tactile_sl_msgs.msg import Contact, Slip

    offline = _offline(tmp_path)
    assert len(offline["wrench"]) >= 2

    proc = ros.start()
    pubs, clouds = _io(ros)
    received: dict[str, dict] = {t: {} for t in TOUCH_TOPICS}
    types = dict(zip(TOUCH_TOPICS, (PointCloud2, WrenchStamped, Contact, Image, Slip)))
    for topic, kind in types.items():
        def keep(msg, topic=topic):
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            received[topic][stamp] = msg
        ros.node.create_subscription(kind, f"/tactile/{topic}", keep, 10)
    markers: dict = {}

    def keep_markers(msg):
        stamp = msg.markers[0].header.stamp
        markers[stamp.sec * 10**9 + stamp.nanosec] = msg
    ros.node.create_subscription(MarkerArray, "/tactile/slip_markers", keep_markers, 10)
    _wait_matched(ros, pubs)
    frames: dict = {}
    for kind, side, m in _bag_messages(4):
        frames.setdefault((m.header.stamp.sec, m.header.stamp.nanosec), []).append((kind, side, m))
    for i, (stamp, parts) in enumerate(sorted(frames.items())):
        def publish(parts=parts):
            for kind, side, m in sorted(parts, key=lambda p: p[0] != "info"):
                pubs[(kind, side)].publish(m)
                ros.spin(0.2 if kind == "info" else 0.02)
        assert _send_until_cloud(ros, clouds, stamp, publish), proc.lines()[-5:]
        if i == 0:   # the reference is prepared beside the frames: outputs start once it is
            assert proc.wait_for_log("fit residual", 30.0, lambda: ros.spin(0.05)), proc.log()
    end = time.monotonic() + 5
    while time.monotonic() < end and min(len(markers), *map(len, received.values())) < len(
            frames) - 1:          # the markers follow each slip message: wait for them too
        ros.spin(0.05)
    assert proc.wait_for_log("no outputs until the reference", 1.0), proc.log()
    assert sum("no outputs until the reference" in line for line in proc.lines()) == 1
    assert proc.wait_for_log("fit residual", 1.0)
    for topic in TOUCH_TOPICS:
        assert len(received[topic]) == len(frames) - 1, (topic, proc.lines()[-5:])
        for stamp, msg in received[topic].items():
            replayed = deserialize_message(offline[topic][stamp], types[topic])
            assert _same(msg, replayed), f"{topic} at {stamp} differs from replay"
    # the RViz markers of the slip state: stamped like slip, the contact disc first
    assert set(markers) == set(received["slip"])
    for stamp, msg in markers.items():
        disc = msg.markers[0]
        assert disc.ns == "slip" and disc.header.frame_id == received["slip"][stamp].header.frame_id
        assert disc.type == Marker.CYLINDER and disc.action == Marker.ADD
        assert disc.scale.x == pytest.approx(2 * received["slip"][stamp].contact_radius)

    client = ros.node.create_client(Trigger, "/tactile/tare")
    assert client.wait_for_service(timeout_sec=10.0)
    future = client.call_async(Trigger.Request())
    end = time.monotonic() + 10
    while not future.done() and time.monotonic() < end:
        ros.spin(0.05)
    assert future.done() and not future.result().success       # the bag's sphere presses
    assert "refused" in future.result().message


def _same(a, b) -> bool:
    """Message equality where NaN equals NaN (the slip message's 'unknown')."""
    if a == b:
        return True
    if not hasattr(a, "get_fields_and_field_types"):
        return isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)
    return type(a) is type(b) and all(_same(getattr(a, f), getattr(b, f))
                                      for f in a.get_fields_and_field_types())


@pytest.mark.parametrize("elastomer, named", [
    ("{youngs_modulus: -3.0e+5, poisson_ratio: 0.49, thickness: 0.0}", "youngs_modulus"),
    # issue 28, item 3: a layer too thin to model; the node died at the first frame
    ("{youngs_modulus: 3.0e+5, poisson_ratio: 0.49, thickness: 1.0e-5}", "thickness")])
def test_bad_sensor_file_is_one_fatal_line(ros, tmp_path, elastomer, named):
    bad = tmp_path / "sensor.yaml"
    bad.write_text(f"tactile_sl_sensor: 1\nelastomer: {elastomer}\n")
    proc = ros.start("-p", f"sensor_file:={bad}")
    code = proc.process.wait(30)
    text = proc.log()
    assert code == 1 and "FATAL" in text and named in text, text
    assert "Traceback" not in text


def test_every_frame_after_the_reference_gets_touch_outputs_paced_as_the_demo(ros, tmp_path):
    """`make demo`'s pacing: all frames pass while the reference is still being prepared.

    The replay sends each frame as soon as the last one's cloud is out, so touch_halfspace's
    five frames are through the decoder within a fraction of the reference's preparation;
    each frame after the reference must still get its wrench (queued, then published with
    its own stamp), equal to the offline replay's.
    """
    from geometry_msgs.msg import WrenchStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import PointCloud2

    from ros_harness import BAGS, running_node

    bag = BAGS / "touch_halfspace.mcap"
    offline = _offline(tmp_path, bag)["wrench"]
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    clouds: dict[int, object] = {}
    wrenches: dict[int, object] = {}

    def stamp(msg):
        return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec

    ros.node.create_subscription(PointCloud2, "/tactile/points",
                                 lambda m: clouds.__setitem__(stamp(m), m), qos)
    ros.node.create_subscription(WrenchStamped, "/tactile/wrench",
                                 lambda m: wrenches.__setitem__(stamp(m), m), qos)
    # the inversion computed, not read back from the disk cache the offline replay filled:
    # the frames must wait for it, as at a first start
    proc = ros.start("-p", "solver_cache:=false")
    assert ros.spin_until(lambda: ros.node.count_publishers("/tactile/points") > 0, 30.0)
    with running_node("tactile_sl_camera", "replay", ros.domain_id, [
            "-r", "__ns:=/tactile", "-p", f"bag:={bag}", "-p", "rate:=0.0",
            "-p", "reliability:=reliable", "-p", "depth:=5",
            "-p", "wait_for_subscribers:=1", "-p", "wait_for_subscribers_timeout:=60.0",
            "-p", "wait_for_topic:=points", "-p", "wait_timeout:=5.0"],
            tmp_path / "replay.log") as replay:
        assert ros.spin_until(lambda: replay.process.poll() is not None, 120.0), replay.log()
    assert len(clouds) == len(offline) + 1, (sorted(clouds), proc.lines()[-5:])
    after_reference = sorted(clouds)[1:]
    assert ros.spin_until(lambda: set(after_reference) <= set(wrenches), 60.0), proc.log()
    assert sorted(wrenches) == after_reference
    for s, msg in wrenches.items():
        assert msg == deserialize_message(offline[s], WrenchStamped), s
