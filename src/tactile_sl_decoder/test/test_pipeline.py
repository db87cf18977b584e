"""StereoPipeline end to end on synthetic geometry, stereo pairing, bag grouping, metrics."""
import array
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from tactile_sl_common.bag_io import BagReader, BagWriter
from tactile_sl_common.camera_info import CameraCalibration, camera_info_fields
from tactile_sl_common.clouds import cloud_fields, cloud_to_arrays, pack_points
from tactile_sl_common.images import image_fields
from tactile_sl_decoder.frames import StampThrottle, StereoSync, bag_frames
from tactile_sl_decoder.glyphs import Glyphs, PipelineInputError
from tactile_sl_decoder.pipeline import PatternSpec, PipelineParams, StereoPipeline
from tactile_sl_decoder.symbol_array import from_message
from tactile_sl_decoder.tooling.e2e_metrics import aggregate, frame_metrics

from ros_harness import REPO
from small_patterns import make_pattern

ARTWORK = REPO / "src" / "tactile_sl_sim" / "artwork" / "pattern.png.yaml"


PATTERN = PatternSpec(make_pattern(), (3, 3), 3, 3, 0.0005)


def _msg(d):
    """Dict (bag field layout) -> attribute object, recursively, like decoded bag messages."""
    if isinstance(d, dict):
        return SimpleNamespace(**{k: _msg(v) for k, v in d.items()})
    return d


@pytest.fixture(scope="module")
def scene():
    """Converging stereo rig ~15 mm from a bumpy pad carrying PATTERN; exact projections."""
    size = (640, 480)
    K1 = np.array([[600.0, 0, 318.0], [0, 600.0, 243.0], [0, 0, 1]])
    K2 = np.array([[605.0, 0, 322.0], [0, 603.0, 238.0], [0, 0, 1]])
    D1 = np.array([-0.08, 0.03, 0.001, -0.0005, 0.0])
    D2 = np.array([-0.07, 0.02, -0.0004, 0.0006, 0.0])
    R_rl, _ = cv2.Rodrigues(np.array([0.0, -0.2, 0.01]))
    T_rl = np.array([-0.006, 0.0002, 0.0006])
    R1, R2, P1, P2, *_ = cv2.stereoRectify(K1, D1, K2, D2, size, R_rl, T_rl.reshape(3, 1),
                                           alpha=0.0, flags=cv2.CALIB_ZERO_DISPARITY)
    left = CameraCalibration(640, 480, K1, D1, R1, P1)
    right = CameraCalibration(640, 480, K2, D2, R2, P2)
    rows, cols = PATTERN.array.shape
    R, C = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    R, C = R.ravel(), C.ravel()
    pitch = PATTERN.pitch_m
    x = (C - (cols - 1) / 2) * pitch + 0.0015
    y = (R - (rows - 1) / 2) * pitch
    z = 0.015 - 0.0006 * np.exp(-((x - 0.001) ** 2 + y ** 2) / (2 * 0.0012 ** 2))   # dent
    X = np.column_stack([x, y, z])
    uv_l, _ = cv2.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K1, D1)
    rvec, _ = cv2.Rodrigues(R_rl)
    uv_r, _ = cv2.projectPoints(X.reshape(-1, 1, 3), rvec, T_rl, K2, D2)
    info_l = _msg(camera_info_fields(left, (5, 6), "left_optical"))
    info_r = _msg(camera_info_fields(right, (5, 6), "right_optical"))
    return SimpleNamespace(X=X, R=R, C=C, uv_l=uv_l.reshape(-1, 2), uv_r=uv_r.reshape(-1, 2),
                           info_l=info_l, info_r=info_r)


def _glyphs(sc, uv, seed, flip=0.0, missing=0.0):
    rng = np.random.default_rng(seed)
    keep = rng.random(len(uv)) >= missing
    lab = PATTERN.array[sc.R, sc.C].copy()
    f = rng.random(len(lab)) < flip
    lab[f] = (lab[f] + rng.integers(1, 3, f.sum())) % 3
    order = rng.permutation(np.flatnonzero(keep))       # detection order is arbitrary
    return Glyphs(uv[order, 0], uv[order, 1], lab[order], np.full(len(order), 0.97),
                  image_width=640, image_height=480), order


def test_symbols_to_points_exact_geometry_and_cells(scene):
    pipe = StereoPipeline(PATTERN, params=PipelineParams(threads=1))
    gl, _ = _glyphs(scene, scene.uv_l, 1, flip=0.03, missing=0.03)
    gr, _ = _glyphs(scene, scene.uv_r, 2, flip=0.03, missing=0.03)
    res = pipe.process_symbols(gl, gr, scene.info_l, scene.info_r)
    pts = res.points
    assert res.frame_id == "left_optical"
    cells = pts["row"].astype(int) * PATTERN.array.shape[1] + pts["col"]
    assert len(np.unique(cells)) == len(cells)
    truth = scene.X[cells]                                # cell index == row-major index
    xyz = np.column_stack([pts["x"], pts["y"], pts["z"]]).astype(np.float64)
    assert np.abs(xyz - truth).max() < 2e-7               # float32 output, exact input
    assert len(pts) >= 0.85 * len(scene.X)


def test_images_path_gives_the_same_points_as_symbols_path(scene):
    """process() with a stand-in extractor/classifier == process_symbols() on its output."""
    gl, _ = _glyphs(scene, scene.uv_l, 3)
    gr, _ = _glyphs(scene, scene.uv_r, 4)
    by_image = {1: gl, 2: gr}

    def extractor(gray, params):
        g = by_image[int(gray[0, 0])]
        patches = np.repeat(g.label[:, None, None], 18 * 18, axis=1).reshape(-1, 18, 18)
        return SimpleNamespace(u=g.u, v=g.v, area=np.ones(len(g)), spacing_px=0.0,
                               patches=patches)

    class Classifier:
        def predict(self, patches):
            return patches[:, 0, 0].astype(np.uint8), np.full(len(patches), 0.97, np.float32)

    pipe = StereoPipeline(PATTERN, Classifier(), PipelineParams(threads=2), extractor=extractor)
    img_l = np.full((480, 640), 1, np.uint8)
    img_r = np.full((480, 640), 2, np.uint8)
    res = pipe.process(img_l, img_r, scene.info_l, scene.info_r)
    ref = StereoPipeline(PATTERN).process_symbols(gl, gr, scene.info_l, scene.info_r)
    assert res.points.tobytes() == ref.points.tobytes()
    assert {"extract", "classify", "decode", "stereo", "total"} <= set(res.timings_ms)
    assert len(res.points) > 0.9 * len(scene.X)

    def flip_all(left, right):
        left.label[:] = (left.label + 1) % 3
    res2 = pipe.process(img_l, img_r, scene.info_l, scene.info_r, label_hook=flip_all)
    assert len(res2.points) == 0                          # all wrong labels: nothing, no guess


def test_bad_inputs_raise_pipeline_input_errors(scene):
    pipe = StereoPipeline(PATTERN, extractor=lambda g, p: None)
    img = np.zeros((480, 640), np.uint8)
    with pytest.raises(PipelineInputError, match="320x240"):
        pipe.process(np.zeros((240, 320), np.uint8), img, scene.info_l, scene.info_r)
    with pytest.raises(PipelineInputError, match="empty"):
        pipe.process(np.zeros((0, 0), np.uint8), img, scene.info_l, scene.info_r)
    bad = _msg(camera_info_fields(CameraCalibration(640, 480, np.zeros((3, 3)), np.zeros(5)),
                                  (0, 0), "x"))
    with pytest.raises(PipelineInputError, match="focal"):
        pipe.process(img, img, bad, scene.info_r)
    with pytest.raises(PipelineInputError, match="baseline"):
        pipe.process(img, img, scene.info_l, scene.info_l)
    g = Glyphs([1.0], [2.0], [0], [1.0], image_width=320, image_height=240)
    with pytest.raises(PipelineInputError, match="320x240"):
        pipe.process_symbols(g, g, scene.info_l, scene.info_r)


def test_stereo_sync_pairs_exact_then_slop_and_bounds_queues():
    s = StereoSync(slop_ns=0, queue_size=2, max_age_ns=10**9)
    assert s.add("left", 100, "L1").pairs == []
    ev = s.add("right", 100, "R1")
    assert ev.pairs == [(100, "L1", "R1")]
    # stale: older than the last paired frame
    assert s.add("right", 50, "R0").dropped[0][2].startswith("stale")
    # unsynchronised: a left frame never gets its partner; bounded queue drops it
    s.add("left", 200, "L2")
    s.add("left", 300, "L3")
    ev = s.add("left", 400, "L4")
    assert [d[1] for d in ev.dropped] == [200]
    ev = s.add("right", 400, "R4")
    assert ev.pairs == [(400, "L4", "R4")]
    assert [d[1] for d in ev.dropped] == [300]               # older unpaired left: dropped
    # slop: nearest within 2 ms, the left stamp is the frame's stamp
    s2 = StereoSync(slop_ns=2_000_000)
    s2.add("right", 1_000_001_000, "R")
    ev = s2.add("left", 1_000_000_000, "L")
    assert ev.pairs == [(1_000_000_000, "L", "R")]
    s3 = StereoSync(slop_ns=0)
    s3.add("right", 1_000_001_000, "R")
    assert s3.add("left", 1_000_000_000, "L").pairs == []
    # time jumps back (a bag played again): start over, do not drop everything as stale
    s4 = StereoSync(max_age_ns=500_000_000)
    s4.add("left", 10 * 10**9, "L")
    assert s4.add("right", 10 * 10**9, "R").pairs
    assert s4.add("left", 10 * 10**9 - 100, "x").dropped[0][2].startswith("stale")
    ev = s4.add("left", 10**9, "L0")
    assert ev.reset and not ev.pairs
    assert s4.add("right", 10**9, "R0").pairs == [(10**9, "L0", "R0")]


def test_stamp_throttle_takes_the_same_frames_of_both_cameras():
    # 30 Hz stamps with +-2 ms jitter, seen by both cameras' nodes
    rng = np.random.default_rng(2)
    stamps = [1_700_000_000 * 10**9 + int(k * 33_333_333 + rng.integers(-2_000_000, 2_000_000))
              for k in range(300)]
    left, right = StampThrottle(15.0), StampThrottle(15.0)
    took_left = [s for s in stamps if left.accept(s)]
    took_right = [s for s in stamps if right.accept(s)]
    assert took_left == took_right
    assert 148 <= len(took_left) <= 152                      # ~15 of every 30
    gaps = np.diff(took_left)
    assert gaps.min() > 20_000_000 and gaps.max() < 110_000_000
    # off: every frame; a bag played again (stamps go back) starts over
    off = StampThrottle(0.0)
    assert all(off.accept(s) for s in stamps[:10])
    again = StampThrottle(10.0)
    assert again.accept(stamps[100]) and not again.accept(stamps[100] + 1)
    assert again.accept(stamps[0])


def test_symbol_array_messages_convert_and_are_checked():
    msg = SimpleNamespace(
        u=array.array("f", [1.0, 2.0]), v=array.array("f", [3.0, 4.0]),
        area=array.array("f", []), label=bytes([0, 255]), confidence=array.array("f", [0.9, 0]),
        row=array.array("i", [-1, -1]), col=array.array("i", [-1, -1]), spacing_px=18.0,
        image_width=640, image_height=480, patch_size=0, patches=b"")
    g = from_message(msg)
    assert g.u.tolist() == [1.0, 2.0] and g.label.tolist() == [0, 255]
    assert g.area.tolist() == [0.0, 0.0] and g.image_width == 640
    msg.patch_size, msg.patches = 18, bytes(2 * 18 * 17)     # wrong-size patches: refused
    with pytest.raises(PipelineInputError, match="patch bytes"):
        from_message(msg)
    msg.patch_size, msg.patches = 0, b""
    msg.v = array.array("f", [3.0])
    with pytest.raises(PipelineInputError, match="field v"):
        from_message(msg)


def test_bag_frames_group_by_exact_stamp_in_any_order(tmp_path, scene):
    calib = CameraCalibration(64, 48, np.diag([50.0, 50.0, 1.0]), np.zeros(5))
    path = tmp_path / "b.mcap"
    rng = np.random.default_rng(0)
    with BagWriter(path) as w:
        for k in range(3):
            stamp = (1700000000, k * 100_000_000 + 7)
            t = stamp[0] * 10**9 + stamp[1]
            parts = []
            for side in ("left", "right"):
                img = dict(image_fields(np.full((48, 64), k, np.uint8)))
                img["header"] = {"stamp": {"sec": stamp[0], "nanosec": stamp[1]},
                                 "frame_id": side}
                parts.append((f"/tactile/{side}/image_raw", "sensor_msgs/msg/Image", img))
                parts.append((f"/tactile/{side}/camera_info", "sensor_msgs/msg/CameraInfo",
                              camera_info_fields(calib, stamp, side)))
            for i in rng.permutation(len(parts)):
                w.write(parts[i][0], parts[i][1], parts[i][2], t)
    frames = list(bag_frames(path))
    assert [f.stamp for f in frames] == [(1700000000, k * 100_000_000 + 7) for k in range(3)]
    assert all(f.left_image.header.frame_id == "left" for f in frames)
    assert all(f.right_info.header.frame_id == "right" for f in frames)
    assert [bytes(f.left_image.data)[0] for f in frames] == [0, 1, 2]
    assert BagReader(path).topics["/tactile/left/image_raw"].message_count == 3


def test_frame_metrics_count_correct_wrong_and_extra():
    gt = pack_points(np.array([[0, 0, 0.015], [0.0005, 0, 0.015], [0.001, 0, 0.015]]),
                     [0, 0, 0], [0, 1, 2])
    out = pack_points(np.array([[0.00001, 0, 0.015],      # cell (0,0): correct, 10 um off
                                [0.001, 0, 0.015],        # claims (0,1) but sits on (0,2)
                                [0.003, 0, 0.015]]),      # (5,5) nowhere near: extra
                      [0, 0, 5], [0, 1, 5])
    m = frame_metrics(out, gt, 0.00025)
    assert (m.visible, m.points, m.correct, m.wrong, m.extra) == (3, 3, 1, 1, 1)
    assert m.errors_m[0] == pytest.approx(1e-5, rel=1e-3)
    msg = _msg(cloud_fields(out, (1, 2), "f"))
    msg.fields = [SimpleNamespace(**f) for f in cloud_fields(out, (1, 2), "f")["fields"]]
    assert cloud_to_arrays(msg).tobytes() == out.tobytes()
    b = aggregate("x", [m, m])
    assert b.correct == 2 and b.wrong == 2 and b.coverage == pytest.approx(1 / 3)


def test_shipped_pattern_decodes_and_matches_the_printed_artwork():
    """The decoder's default pattern is the one the pad (and the bundled bags) carry."""
    import yaml

    spec = PatternSpec.load()
    meta = yaml.safe_load(ARTWORK.read_text())
    art = np.array([[int(ch) for ch in row] for row in meta["array"]], np.uint8)
    assert np.array_equal(spec.array, art)
    assert spec.window == tuple(meta["window"]) and spec.min_hamming == meta["min_hamming"]
    pipe = StereoPipeline(spec)
    assert len(pipe.codebook.windows) == (spec.array.shape[0] - 2) * (spec.array.shape[1] - 2)


def test_demo_pictures(scene):
    from tactile_sl_decoder.tooling.pictures import render_cloud, render_overlay

    pipe = StereoPipeline(PATTERN)
    gl, _ = _glyphs(scene, scene.uv_l, 5)
    gr, _ = _glyphs(scene, scene.uv_r, 6)
    res = pipe.process_symbols(gl, gr, scene.info_l, scene.info_r)
    over = render_overlay(np.zeros((480, 640), np.uint8), res.left)
    assert over.shape == (480, 640, 3) and over.any()
    cloud = render_cloud(res.points)
    assert cloud.shape == (480, 640, 3) and (cloud != 255).any()
    assert render_cloud(res.points[:0]).shape == (480, 640, 3)


def test_e2e_section_reports_per_frame_and_per_bag(tmp_path):
    """The `tactile-sl evaluate` section runs the pipeline over a bundled bag."""
    import argparse
    import json

    from tactile_sl_decoder.cli.evaluate_cmd import e2e_section

    bag = REPO / "bags" / "no_contact.mcap"
    args = argparse.Namespace(pattern=None, weights=None, namespace="/tactile", max_frames=1,
                              totals_only=False, json=tmp_path / "ev.json")
    text = e2e_section(args, [bag])
    assert "coverage" in text and "no_contact" in text
    doc = json.loads((tmp_path / "ev.e2e.json").read_text())
    assert doc["bags"][0]["frames"] == 1 and doc["bags"][0]["visible"] > 500
    assert len(doc["frames"]) == 1 and doc["frames"][0]["bag"] == "no_contact"
