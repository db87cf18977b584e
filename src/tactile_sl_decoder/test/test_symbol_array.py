"""Glyphs <-> SymbolArray conversions round-trip for dicts, bag objects and rclpy."""
import array
import types

import numpy as np
import pytest

from tactile_sl_decoder.contract import CELL_UNKNOWN, LABEL_UNKNOWN, PATCH_SIZE
from tactile_sl_decoder.extract.extraction import Detections, extract_symbols
from tactile_sl_decoder.glyphs import Glyphs, PipelineInputError
from tactile_sl_decoder.symbol_array import (
    SymbolArrayError,
    fill_message,
    from_message,
    to_fields,
)
from tactile_sl_decoder.tooling.synth_glyphs import synth_image


def _detections(n=5):
    rng = np.random.default_rng(n)
    return Detections(rng.uniform(0, 640, n).astype(np.float32),
                      rng.uniform(0, 480, n).astype(np.float32),
                      rng.uniform(20, 80, n).astype(np.float32), 17.5,
                      rng.integers(0, 256, (n, 18, 18), dtype=np.uint8))


def _same(a: Glyphs, b: Glyphs):
    for key in ("u", "v", "area", "label", "confidence", "row", "col"):
        x, y = getattr(a, key), getattr(b, key)
        assert x.dtype == y.dtype and np.array_equal(x, y), key
    assert a.spacing_px == pytest.approx(b.spacing_px)
    assert (a.image_width, a.image_height) == (b.image_width, b.image_height)
    if a.patches is None:
        assert b.patches is None
    else:
        assert np.array_equal(a.patches, b.patches)


def _bag_object(fields):
    """What a bag reader decodes: lists for float/int arrays, bytes for uint8[]."""
    obj = types.SimpleNamespace(**{k: (v.tolist() if isinstance(v, np.ndarray) else v)
                                   for k, v in fields.items()})
    obj.label = bytes(fields["label"].tobytes())
    return obj


def test_dict_roundtrip_with_defaults_and_values():
    det = _detections()
    glyphs = Glyphs.from_detections(det, (480, 640))
    assert (glyphs.label == LABEL_UNKNOWN).all() and (glyphs.row == CELL_UNKNOWN).all()
    assert (glyphs.confidence == 0).all() and (glyphs.image_width, glyphs.image_height) == (
        640, 480)
    _same(glyphs, from_message(to_fields(glyphs)))
    labelled = Glyphs.from_detections(det, (480, 640), label=[0, 1, 2, 255, 1],
                                      confidence=[0.99, 0.5, 1, 0.1, 0.95],
                                      row=[1, 2, 3, -1, 5], col=[4, 3, 2, -1, 0],
                                      with_patches=False)
    fields = to_fields(labelled)
    assert fields["patch_size"] == 0 and fields["patches"] == b""
    back = from_message(fields)
    _same(labelled, back)
    assert np.array_equal(back.to_detections().u, det.u)
    assert back.to_detections().patches.shape == (0, PATCH_SIZE, PATCH_SIZE)


def test_the_writer_chooses_whether_patches_travel():
    glyphs = Glyphs.from_detections(_detections(4), (480, 640))
    with_patches, without = to_fields(glyphs), to_fields(glyphs, with_patches=False)
    assert with_patches["patch_size"] == 18 and len(with_patches["patches"]) == 4 * 18 * 18
    assert without["patch_size"] == 0 and without["patches"] == b""
    assert glyphs.patches is not None          # the record keeps them either way


def test_bag_style_object_roundtrip():
    """Bag-decoded messages expose bytes / lists as attributes."""
    glyphs = Glyphs.from_detections(_detections(7), (480, 640), label=np.arange(7) % 3)
    back = from_message(_bag_object(to_fields(glyphs)))
    _same(glyphs, back)
    back.label[0] = 2                           # arrays read from bytes are the reader's own
    assert back.label[0] == 2


def test_real_extraction_roundtrip():
    img = synth_image(np.random.default_rng(0), spacing=18.0)
    det = extract_symbols(img.gray)
    glyphs = Glyphs.from_detections(det, img.gray.shape)
    back = from_message(to_fields(glyphs))
    _same(glyphs, back)
    assert back.patches.shape == (len(det), 18, 18)
    assert np.array_equal(back.to_detections().area, det.area)


def test_empty_optional_arrays_take_the_defaults():
    """label, area, confidence, row, col may be left empty (not carried); u, v may not."""
    msg = types.SimpleNamespace(
        u=array.array("f", [1.0, 2.0]), v=array.array("f", [3.0, 4.0]),
        area=array.array("f", []), label=b"", confidence=array.array("f", []),
        row=array.array("i", []), col=array.array("i", [5, 6]), spacing_px=18.0,
        image_width=640, image_height=480, patch_size=0, patches=b"")
    g = from_message(msg)
    assert g.u.tolist() == [1.0, 2.0] and g.v.tolist() == [3.0, 4.0]
    assert g.label.tolist() == [LABEL_UNKNOWN] * 2 and g.label.dtype == np.uint8
    assert g.area.tolist() == [0.0, 0.0] and g.confidence.tolist() == [0.0, 0.0]
    assert g.row.tolist() == [CELL_UNKNOWN] * 2 and g.col.tolist() == [5, 6]
    assert g.patches is None and (g.image_width, g.spacing_px) == (640, 18.0)
    msg.v = array.array("f", [])
    with pytest.raises(SymbolArrayError, match="field v has 0 values"):
        from_message(msg)


def test_inconsistent_messages_raise_one_error_class():
    fields = to_fields(Glyphs.from_detections(_detections(), (480, 640)))
    with pytest.raises(SymbolArrayError, match="field v has 3 values"):
        from_message(dict(fields, v=fields["v"][:3]))
    with pytest.raises(SymbolArrayError, match="field row has 2 values"):
        from_message(dict(fields, row=fields["row"][:2]))
    with pytest.raises(SymbolArrayError, match="patch bytes"):
        from_message(dict(fields, patch_size=16))
    with pytest.raises(SymbolArrayError, match="patch_size 0"):
        from_message(dict(fields, patch_size=0))
    with pytest.raises(SymbolArrayError, match="patch bytes"):
        from_message(dict(fields, patches=fields["patches"][:-1]))
    # nodes catch PipelineInputError for every input problem, this one included
    with pytest.raises(PipelineInputError, match="patch bytes"):
        from_message(_bag_object(dict(fields, patch_size=17)))
    with pytest.raises(PipelineInputError, match="'label' has 2 values"):
        Glyphs.from_detections(_detections(), (480, 640), label=[1, 2])
    with pytest.raises(PipelineInputError, match="patches have shape"):
        Glyphs([1.0, 2.0], [3.0, 4.0], patches=np.zeros((2, 18, 17), np.uint8))


def test_rclpy_message_roundtrip():
    from std_msgs import msg as std

    from tactile_sl_msgs import msg as msg_mod
    glyphs = Glyphs.from_detections(_detections(6), (480, 640), label=[0, 1, 2, 0, 1, 255],
                                    confidence=np.linspace(0, 1, 6), row=np.arange(6),
                                    col=np.arange(6)[::-1])
    header = std.Header(frame_id="left_optical")
    header.stamp.sec, header.stamp.nanosec = 12, 345
    msg = fill_message(msg_mod.SymbolArray(), glyphs, header=header)
    assert msg.header.frame_id == "left_optical" and msg.header.stamp.nanosec == 345
    assert msg.patch_size == 18 and len(msg.patches) == 6 * 18 * 18
    _same(glyphs, from_message(msg))
    bare = fill_message(msg_mod.SymbolArray(), glyphs, with_patches=False)
    assert bare.patch_size == 0 and len(bare.patches) == 0
    assert from_message(bare).patches is None
    empty = fill_message(msg_mod.SymbolArray(), Glyphs.from_detections(
        Detections.empty(), (480, 640)))
    assert len(from_message(empty)) == 0
