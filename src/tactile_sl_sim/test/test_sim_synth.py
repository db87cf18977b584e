"""Scenes, contact mechanics and synthesised bags."""
import pathlib

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from tactile_sl_common.bag_io import BagReader
from tactile_sl_sim.artwork import random_values, write_artwork
from tactile_sl_sim.cli import synth_cmd
from tactile_sl_sim.contact import Contact, FieldGrid, PadParams
from tactile_sl_sim.scenes import SceneError, load_scenes

from ros_harness import BAGS

SCENES = """
defaults: {fps: 20, seed: 3, nuisances: {noise_sigma: 1.0}}
scenes:
  - name: press
    frames: 3
    contacts:
      - indenter: {kind: sphere, radius: 0.004}
        keyframes:
          - {frame: 0, depth: 0.0}
          - {frame: 2, depth: 0.0006, shear: [0.0001, 0.0]}
  - name: colour
    frames: 1
    encoding: bgr8
"""
TOPICS = ["/tactile/left/image_raw", "/tactile/right/image_raw", "/tactile/left/camera_info",
          "/tactile/right/camera_info", "/tactile/ground_truth/points"]


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    root = tmp_path_factory.mktemp("synth")
    art = write_artwork(root / "art.png", random_values(30, 28, seed=4))
    scenes = root / "scenes.yaml"
    scenes.write_text(SCENES)
    import argparse

    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    synth_cmd.register(sub)
    args = parser.parse_args(["synth", str(scenes), "-o", str(root / "out"), "--artwork",
                              str(art)])
    assert args.func(args) == 0
    first = {p.name: p.read_bytes() for p in (root / "out").glob("*.mcap")}
    assert args.func(args) == 0  # again: byte-for-byte identical
    second = {p.name: p.read_bytes() for p in (root / "out").glob("*.mcap")}
    assert first == second
    return root / "out"


@pytest.mark.slow
def test_bag_topics_stamps_and_ground_truth(bags):
    reader = BagReader(bags / "press.mcap")
    reader.require_topics(TOPICS)
    assert all(reader.topics[t].message_count == 3 for t in TOPICS)
    stamps: dict[int, dict[str, tuple[int, int]]] = {}
    for raw, msg in reader.messages(TOPICS):
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        assert raw.log_time_ns == stamp[0] * 10**9 + stamp[1]
        stamps.setdefault(raw.log_time_ns, {})[raw.topic] = stamp
        if raw.topic.endswith("points"):
            assert msg.header.frame_id == "tactile_left_optical_frame"
            assert msg.width > 500 and msg.is_dense
        if raw.topic.endswith("camera_info"):
            assert msg.distortion_model == "plumb_bob" and len(msg.d) == 5
    assert len(stamps) == 3
    assert sorted(stamps)[1] - sorted(stamps)[0] == 50_000_000  # 20 fps, exact
    assert all(len(v) == 5 for v in stamps.values())


@pytest.mark.slow
def test_bag_opens_with_an_independent_reader(bags):
    with open(bags / "colour.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        assert header.profile == "ros2"
        seen = {}
        for schema, channel, _message, decoded in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            assert "offered_qos_profiles" in channel.metadata
            seen[channel.topic] = decoded
    assert set(seen) == set(TOPICS)
    assert seen["/tactile/left/image_raw"].encoding == "bgr8"


def test_hertz_profile_is_smooth_and_physical():
    pad = PadParams(thickness=0.002, poisson=0.5)
    c = Contact("sphere", radius=0.005, depth=0.0004)
    a = c.contact_radius()
    r = np.linspace(0, 4 * a, 4001)
    d = c.displacement(r, np.zeros_like(r), pad)
    w = -d[:, 2]
    assert w[0] == pytest.approx(0.0004)
    i = np.searchsorted(r, a)
    assert w[i] == pytest.approx(0.0002, rel=2e-3)  # Hertz: half the depth at the edge
    eps = 1e-6 * a
    edge = np.array([a - 2 * eps, a - eps, a + eps, a + 2 * eps])
    we = -c.displacement(edge, np.zeros(4), pad)[:, 2]
    inner, outer = (we[1] - we[0]) / eps, (we[3] - we[2]) / eps
    assert inner == pytest.approx(-a / c.radius, rel=1e-3)
    assert outer == pytest.approx(inner, rel=1e-2)  # same slope both sides: no kink
    assert np.all(np.diff(w) <= 1e-15) and w[-1] > 0  # monotone, deforms beyond the contact
    assert np.abs(d[:, 0]).max() < 1e-12  # incompressible, no shear: no lateral motion
    compressible = Contact("sphere", radius=0.005, depth=0.0004, shear=(1e-4, 0))
    dd = compressible.displacement(r, np.zeros_like(r), PadParams(poisson=0.4))
    assert dd[0, 0] == pytest.approx(1e-4)  # sticking contact moves with the indenter


def test_contacts_superpose_and_decay():
    pad = PadParams()
    a = Contact("sphere", radius=0.003, depth=0.0005, x=-0.003)
    b = Contact("flat", radius=0.001, depth=0.0003, x=0.003, fillet=0.0)
    both = FieldGrid.build([a, b], pad)
    only = FieldGrid.build([a], pad).data + FieldGrid.build([b], pad).data
    np.testing.assert_allclose(both.data, only, atol=1e-15)
    far = both.sample(np.array([0.012]), np.array([0.0095]))
    assert np.abs(far).max() < 1e-9
    assert both.sample(np.array([0.003]), np.array([0.0]))[0, 2] == pytest.approx(-0.0003, abs=1e-6)
    with pytest.raises(ValueError, match="unknown indenter"):
        Contact("cube")


@pytest.mark.parametrize("text, message", [
    ("scenes: [{name: a, framez: 2}]", "unknown key"),
    ("scenes: [{name: a, contacts: [{indenter: {kind: blob}}]}]", "unknown indenter"),
    ("scenes: [{name: a, contacts: [{indenter: {kind: sphere}, keyframes: "
     "[{frame: 2}, {frame: 1}]}]}]", "increase"),
    ("scenes: [{name: a, encoding: rgb16}]", "encoding"),
    ("scenes: [{name: a}, {name: a}]", "unique"),
    ("nothing: here", "scenes"),
])
def test_bad_scenes_are_clear_errors(tmp_path: pathlib.Path, text, message):
    p = tmp_path / "s.yaml"
    p.write_text(text)
    with pytest.raises(SceneError, match=message):
        load_scenes(p)


def test_bundled_scenes_file_is_valid():
    scenes = load_scenes(BAGS / "scenes.yaml")
    assert {s.name for s in scenes} == {"no_contact", "sphere_shallow_wide", "sphere_deep_small",
                                        "edge", "two_contacts", "harsh_lighting"}


def test_bundled_bags_are_small_complete_and_readable():
    root = BAGS
    bags = sorted(root.glob("*.mcap"))
    assert {b.stem for b in bags} >= {"no_contact", "sphere_shallow_wide", "sphere_deep_small",
                                       "edge", "two_contacts", "harsh_lighting"}
    for bag in bags:
        assert bag.stat().st_size < 5_000_000, bag
        with open(bag, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            assert reader.get_header().profile == "ros2"
            counts = summary.statistics.channel_message_counts
            topics = {c.topic: counts[cid] for cid, c in summary.channels.items()}
        assert set(topics) >= set(TOPICS), bag      # touch bags add ground_truth topics
        assert len(set(topics.values())) == 1  # every topic once per frame
