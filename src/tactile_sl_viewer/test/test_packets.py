"""The page's binary message: header + aligned blobs; each part converted once per frame."""
import cv2
import numpy as np
import viewer_messages as msgs

from tactile_sl_viewer.assembly import FrameParts
from tactile_sl_viewer.packets import PacketBuilder, pack, stamp_text, unpack

S = 1_000_000_000


def test_blobs_are_aligned_and_come_back_as_they_went():
    a = np.arange(7, dtype=np.float32)
    b = np.array([[1, 2, 3]], np.uint8)
    message = pack({"type": "frame", "x": 1}, [("b", b, "u1"), ("a", a, "f4"),
                                               ("j", b"\xff\xd8\xff", "jpeg")])
    header, blobs = unpack(message)
    assert header["x"] == 1
    assert all(entry["offset"] % 4 == 0 for entry in header["blobs"])
    assert blobs["a"].tolist() == a.tolist() and blobs["b"].tolist() == [[1, 2, 3]]
    assert blobs["j"] == b"\xff\xd8\xff"


def test_stamps_are_exact_text():
    assert stamp_text(1_796_221_451_014_312_890) == "1796221451.014312890"
    assert stamp_text(5 * S + 7) == "5.000000007"


def frame(stamp=3 * S):
    parts = {"image": msgs.image(stamp), "glyphs": msgs.symbols(stamp),
             "points": msgs.points(stamp), "wrench": msgs.wrench(stamp),
             "contact": msgs.contact(stamp, cells=2),
             "field": msgs.field(stamp, {(1, 1): -0.02, (1, 2): -0.01, (3, 3): -0.001})}
    return FrameParts(stamp, parts, 0.0)


def test_a_frame_carries_image_glyphs_pressure_contact_cells_and_numbers():
    builder = PacketBuilder(msgs.PAD, "tactile")
    header, blobs = unpack(builder.build(frame(), {"decoded_hz": 30.0}))
    assert header["stamp"] == "3.000000000"
    assert header["stats"] == {"decoded_hz": 30.0}
    assert header["wrench"]["force"] == [0.0, 0.0, -1.25]
    assert header["points"] == 3 and header["glyphs"] == {"count": 4, "decoded": 2}
    gray = cv2.imdecode(np.frombuffer(blobs["image"], np.uint8), cv2.IMREAD_GRAYSCALE)
    assert gray.shape == (48, 64) and abs(int(gray[0, 0]) - 128) < 3
    assert blobs["pressure"].shape == (msgs.PAD.rows, msgs.PAD.cols)
    assert np.argwhere(blobs["contact_cells"]).tolist() == [[1, 1], [1, 2]]
    assert header["map"]["kind"] == "pressure" and header["map"]["vmax"] >= 10.0
    assert header["errors"] == []


def test_depth_map_on_request_and_figures_only_without_a_frame():
    builder = PacketBuilder(msgs.PAD)
    f = frame()
    f.parts["depth"] = msgs.depth(f.stamp_ns, np.full((3, 4), 2e-5))
    header, blobs = unpack(builder.build(f, {}, "depth"))
    assert header["map"]["kind"] == "depth" and blobs["depth"][0, 0] == np.float32(20.0)
    assert "pressure" not in blobs
    header, blobs = unpack(builder.build(None, {"camera_hz": 5.0}))
    assert "stamp" not in header and blobs == {} and header["stats"]["camera_hz"] == 5.0


def test_each_part_is_converted_once_however_often_it_is_sent():
    builder = PacketBuilder(msgs.PAD)
    f = frame()
    for _ in range(3):
        builder.build(f, {})
    assert builder.encoded == 1
    builder.build(frame(4 * S), {})
    assert builder.encoded == 2


def test_a_bad_part_is_left_out_with_its_reason():
    errors = []
    builder = PacketBuilder(msgs.PAD, on_error=errors.append)
    f = frame()
    f.parts["image"].encoding = "yuv422"
    header, blobs = unpack(builder.build(f, {}))
    assert "image" not in blobs and "wrench" in header
    assert len(header["errors"]) == 1 and "yuv422" in header["errors"][0]
    assert errors == header["errors"]
