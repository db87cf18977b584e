"""symbol_extractor -> symbol_classifier as two processes over loopback DDS; bad input skipped.

Both installed executables run on a ROS domain of their own with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST; this test process publishes images and
SymbolArrays and listens for the labelled output.
"""
import contextlib
import time

import numpy as np
import pytest
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import Image

from tactile_sl_common.images import image_fields
from tactile_sl_decoder.tooling.synth_glyphs import synth_image
from tactile_sl_msgs.msg import SymbolArray

from ros_harness import Probe, running_node

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_chain_labels_images_and_survives_bad_input(tmp_path, domain_id):
    stack = contextlib.ExitStack()
    try:
        nodes = [stack.enter_context(running_node("tactile_sl_decoder", name, domain_id,
                                                  ["-r", "__ns:=/t"], tmp_path / f"{name}.log"))
                 for name in ("symbol_extractor", "symbol_classifier")]
        procs = [n.process for n in nodes]
        probe = stack.enter_context(Probe("probe", domain_id, namespace="/t"))
        node, ex = probe.node, probe.executor
        got = []
        node.create_subscription(SymbolArray, "labelled_symbols", got.append,
                                 QoSProfile(depth=50))
        images = node.create_publisher(Image, "image", qos_profile_sensor_data)
        symbols = node.create_publisher(SymbolArray, "symbols", QoSProfile(depth=10))

        def spin_until(pred, timeout):
            end = time.monotonic() + timeout
            while time.monotonic() < end and not pred():
                ex.spin_once(timeout_sec=0.05)
                assert all(p.poll() is None for p in procs), "a node died"
            return pred()

        assert spin_until(lambda: images.get_subscription_count() > 0
                          and symbols.get_subscription_count() > 0
                          and node.count_publishers("labelled_symbols") > 0, 30.0)

        def image(sec, **over):
            img = synth_image(np.random.default_rng(sec), spacing=18.0)
            msg = Image(**{k: v for k, v in image_fields(img.gray).items()})
            msg.header.stamp.sec = sec
            msg.header.frame_id = "left_optical"
            for k, v in over.items():
                setattr(msg, k, v)
            return msg, img

        bad = [image(1, encoding="32FC1")[0], image(2, height=0, width=0, step=0, data=b"")[0],
               image(3, data=b"\0" * 100)[0]]
        for msg in bad:
            images.publish(msg)
        good, truth = image(10)
        # best effort: publish until the labelled result of the good image comes back
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and not any(m.header.stamp.sec == 10 for m in got):
            images.publish(good)
            spin_until(lambda: any(m.header.stamp.sec == 10 for m in got), 1.0)
        out = [m for m in got if m.header.stamp.sec == 10]
        assert out, "no labelled SymbolArray for the good image"
        assert not any(m.header.stamp.sec in (1, 2, 3) for m in got)
        m = out[0]
        assert m.header.frame_id == "left_optical"
        assert (m.image_width, m.image_height) == (640, 480)
        n = len(m.u)
        assert abs(n - len(truth.u)) < 0.05 * len(truth.u)
        assert len(m.label) == n and len(m.confidence) == n and m.patch_size == 0
        labels = np.frombuffer(bytes(m.label), np.uint8) if isinstance(
            m.label, (bytes, bytearray)) else np.asarray(m.label)
        assert (labels < 3).mean() > 0.95  # classified, not left unknown
        assert m.spacing_px == pytest.approx(18.0, rel=0.12)

        # classifier input it cannot use: 16 px patches, and arrays of different lengths
        wrong = SymbolArray()
        wrong.header.stamp.sec = 20
        wrong.u = wrong.v = wrong.area = wrong.confidence = [1.0, 2.0]
        wrong.label = [255, 255]
        wrong.row = wrong.col = [-1, -1]
        wrong.patch_size = 16
        wrong.patches = bytes(2 * 16 * 16)
        symbols.publish(wrong)
        ragged = SymbolArray()
        ragged.header.stamp.sec = 21
        ragged.u = [1.0]
        symbols.publish(ragged)
        ok = SymbolArray()
        ok.header.stamp.sec = 22
        assert spin_until(lambda: False, 0.3) is False
        symbols.publish(ok)  # an empty array is valid and passes through
        assert spin_until(lambda: any(m.header.stamp.sec == 22 for m in got), 10.0)
        assert not any(m.header.stamp.sec in (20, 21) for m in got)
        assert all(p.poll() is None for p in procs)
    except AssertionError as exc:  # say what the nodes said
        text = "\n".join(f"--- {n.log_path.stem}\n{n.log()[-3000:]}" for n in nodes)
        raise AssertionError(f"{exc}\n{text}") from None
    finally:
        stack.close()   # the probe, then the nodes
    text = {n.log_path.stem: n.log() for n in nodes}
    assert "skipping image" in text["symbol_extractor"]
    assert "skipping SymbolArray" in text["symbol_classifier"]
    assert "Traceback" not in "".join(text.values())


def test_extractor_max_rate_takes_frames_by_stamp(tmp_path, domain_id):
    """``max_rate`` 2: of ten images stamped 0.1 s apart, those of the two 0.5 s slots' first
    stamps are extracted (what the other camera's extractor takes too)."""
    with running_node("tactile_sl_decoder", "symbol_extractor", domain_id,
                      ["-r", "__ns:=/t", "-p", "max_rate:=2.0", "-p", "publish_patches:=false"],
                      tmp_path / "extractor.log") as extractor, \
            Probe("probe", domain_id, namespace="/t") as probe:
        got: list[SymbolArray] = []
        probe.node.create_subscription(SymbolArray, "symbols", got.append, QoSProfile(depth=50))
        images = probe.node.create_publisher(Image, "image", qos_profile_sensor_data)
        assert probe.spin_until(lambda: images.get_subscription_count() > 0
                                and probe.node.count_publishers("symbols") > 0, 30.0)
        gray = synth_image(np.random.default_rng(0), spacing=18.0).gray
        for k in range(10):
            msg = Image(**image_fields(gray))
            msg.header.stamp.sec, msg.header.stamp.nanosec = 30, k * 100_000_000
            for _ in range(3):          # best effort: each stamp sent thrice, taken once
                images.publish(msg)
                probe.spin(0.05)
        probe.spin_until(lambda: len(got) >= 2, 10.0)
        probe.spin(0.5)
        assert extractor.process.poll() is None
    stamps = sorted((m.header.stamp.sec, m.header.stamp.nanosec) for m in got)
    assert stamps == [(30, 0), (30, 500_000_000)], stamps
