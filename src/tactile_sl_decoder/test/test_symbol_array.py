"""Detections <-> SymbolArray conversions round-trip for dicts, bag objects and rclpy."""
import types

import numpy as np
import pytest

from tactile_sl_decoder.contract import CELL_UNKNOWN, LABEL_UNKNOWN
from tactile_sl_decoder.extract.extraction import Detections, extract_symbols
from tactile_sl_decoder.symbol_array import (
    SymbolArrayError,
    Symbols,
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


def _same(a: Symbols, b: Symbols):
    for key in ("u", "v", "area", "label", "confidence", "row", "col"):
        x, y = getattr(a, key), getattr(b, key)
        assert x.dtype == y.dtype and np.array_equal(x, y), key
    assert a.spacing_px == pytest.approx(b.spacing_px)
    assert (a.image_width, a.image_height) == (b.image_width, b.image_height)
    if a.patches is None:
        assert b.patches is None
    else:
        assert np.array_equal(a.patches, b.patches)


def test_dict_roundtrip_with_defaults_and_values():
    det = _detections()
    sym = Symbols.from_detections(det, (480, 640))
    assert (sym.label == LABEL_UNKNOWN).all() and (sym.row == CELL_UNKNOWN).all()
    assert (sym.confidence == 0).all()
    _same(sym, from_message(to_fields(sym)))
    labelled = Symbols.from_detections(det, (480, 640), label=[0, 1, 2, 255, 1],
                                       confidence=[0.99, 0.5, 1, 0.1, 0.95],
                                       row=[1, 2, 3, -1, 5], col=[4, 3, 2, -1, 0],
                                       with_patches=False)
    fields = to_fields(labelled)
    assert fields["patch_size"] == 0 and fields["patches"] == b""
    back = from_message(fields)
    _same(labelled, back)
    assert np.array_equal(back.to_detections().u, det.u)


def test_bag_style_object_roundtrip():
    """Bag-decoded messages expose bytes / lists as attributes."""
    sym = Symbols.from_detections(_detections(7), (480, 640), label=np.arange(7) % 3)
    fields = to_fields(sym)
    obj = types.SimpleNamespace(**{k: (v.tolist() if isinstance(v, np.ndarray) else v)
                                   for k, v in fields.items()})
    obj.label = bytes(fields["label"].tobytes())  # uint8[] decodes as bytes
    _same(sym, from_message(obj))


def test_real_extraction_roundtrip():
    img = synth_image(np.random.default_rng(0), spacing=18.0)
    det = extract_symbols(img.gray)
    sym = Symbols.from_detections(det, img.gray.shape)
    back = from_message(to_fields(sym))
    _same(sym, back)
    assert back.patches.shape == (len(det), 18, 18)


def test_inconsistent_messages_raise():
    fields = to_fields(Symbols.from_detections(_detections(), (480, 640)))
    bad = dict(fields, v=fields["v"][:3])
    with pytest.raises(SymbolArrayError, match="field v has 3 values"):
        from_message(bad)
    with pytest.raises(SymbolArrayError, match="patch bytes"):
        from_message(dict(fields, patch_size=16))
    with pytest.raises(SymbolArrayError, match="patch_size 0"):
        from_message(dict(fields, patch_size=0))
    with pytest.raises(SymbolArrayError):
        Symbols.from_detections(_detections(), (480, 640), label=[1, 2])


def test_rclpy_message_roundtrip():
    msg_mod = pytest.importorskip("tactile_sl_msgs.msg")
    std = pytest.importorskip("std_msgs.msg")
    sym = Symbols.from_detections(_detections(6), (480, 640), label=[0, 1, 2, 0, 1, 255],
                                  confidence=np.linspace(0, 1, 6), row=np.arange(6),
                                  col=np.arange(6)[::-1])
    header = std.Header(frame_id="left_optical")
    header.stamp.sec, header.stamp.nanosec = 12, 345
    msg = fill_message(msg_mod.SymbolArray(), sym, header=header)
    assert msg.header.frame_id == "left_optical" and msg.header.stamp.nanosec == 345
    assert msg.patch_size == 18 and len(msg.patches) == 6 * 18 * 18
    _same(sym, from_message(msg))
    empty = fill_message(msg_mod.SymbolArray(), Symbols.from_detections(
        Detections.empty(), (480, 640)))
    assert len(from_message(empty)) == 0
