"""Classifier: fast path equals torch, weights loading is strict, shipped weights work."""
import numpy as np
import pytest
import torch

from tactile_sl_decoder.classify.classifier import (
    DEFAULT_THRESHOLD,
    FORMAT,
    FORMAT_VERSION,
    LENET_ARCH,
    TINY_ARCH,
    Classifier,
    ClassifierError,
    FastLeNet,
    FastTiny,
    default_weights_path,
)
from tactile_sl_decoder.classify.model import GlyphNet, GlyphNetTiny, standardise
from tactile_sl_decoder.contract import LABEL_UNKNOWN
from tactile_sl_decoder.extract.extraction import extract_symbols
from tactile_sl_decoder.tooling.synth_glyphs import synth_image
from tactile_sl_decoder.tooling.training import label_detections, save_blob


def _blob(model: GlyphNet, **over):
    blob = {"format": FORMAT, "version": FORMAT_VERSION, "arch": LENET_ARCH, "classes": 3,
            "primitives": ["line", "circle", "triangle"], "threshold": 0.9,
            "state_dict": {k: v.clone() for k, v in model.state_dict().items()}, "meta": {}}
    blob.update(over)
    return blob


@pytest.mark.parametrize("classes,n", [(3, 257), (5, 1), (3, 0)])
def test_fast_path_matches_torch(classes, n):
    torch.manual_seed(classes)
    model = GlyphNet(classes).eval()
    with torch.no_grad():  # larger weights than init so that every layer matters
        for p in model.parameters():
            p.mul_(3.0)
    patches = np.random.default_rng(n).integers(0, 256, (n, 18, 18), dtype=np.uint8)
    with torch.no_grad():
        ref = model(standardise(torch.from_numpy(patches))).numpy() if n else np.zeros((0,))
    fast = FastLeNet.from_state({k: v.numpy() for k, v in model.state_dict().items()})
    out = fast.logits(patches)
    assert out.shape == (n, classes)
    if n:
        assert np.abs(out - ref).max() < 1e-4 * max(1.0, np.abs(ref).max())


@pytest.mark.parametrize("classes,n,channels,hidden", [
    (3, 600, 16, 32), (5, 1, 8, 24), (3, 0, 16, 32), (3, 512, 4, 7), (3, 1100, 16, 32)])
def test_tiny_fast_path_matches_torch(classes, n, channels, hidden):
    """Blocks of 512 patches, odd sizes, one patch, none: the same logits as torch."""
    torch.manual_seed(classes + n)
    model = GlyphNetTiny(classes, channels, hidden).eval()
    with torch.no_grad():
        for p in model.parameters():
            p.mul_(3.0)
    patches = np.random.default_rng(n).integers(0, 256, (n, 18, 18), dtype=np.uint8)
    patches[:1] = 77                                 # a flat patch (zero variance) too
    with torch.no_grad():
        ref = model(standardise(torch.from_numpy(patches))).numpy() if n else np.zeros((0,))
    fast = FastTiny.from_state({k: v.numpy() for k, v in model.state_dict().items()})
    out = fast.logits(patches)
    assert out.shape == (n, classes)
    if n:
        assert np.abs(out - ref).max() < 1e-4 * max(1.0, np.abs(ref).max())


def test_tiny_weights_load_and_mismatches_are_refused(tmp_path):
    model = GlyphNetTiny(3).eval()
    path = tmp_path / "tiny.pt"
    save_blob(_blob(model, arch=TINY_ARCH), path)
    clf = Classifier.load(path)
    assert isinstance(clf.net, FastTiny) and clf.classes == 3
    bad = {**model.state_dict(), "fc1.weight": torch.zeros(32, 100)}
    torch.save(_blob(model, arch=TINY_ARCH, state_dict=bad), path)
    with pytest.raises(ClassifierError, match=r"fc1\.weight has shape \(32, 100\), expected "
                                              r"\(32, 256\)"):
        Classifier.load(path)
    torch.save(_blob(GlyphNet(3), arch=TINY_ARCH), path)     # LeNet weights, tiny tag
    with pytest.raises(ClassifierError, match=r"conv1\.weight has shape \(6, 1, 5, 5\), expected "
                                              r"\(6, 1, 3, 3\) for tiny9-18"):
        Classifier.load(path)


def test_load_roundtrip_and_threshold(tmp_path):
    model = GlyphNet(3).eval()
    path = tmp_path / "w.pt"
    save_blob(_blob(model), path)
    clf = Classifier.load(path)
    assert clf.classes == 3 and clf.threshold == 0.9
    patches = np.random.default_rng(0).integers(0, 256, (50, 18, 18), dtype=np.uint8)
    prob = clf.probabilities(patches)
    assert prob.shape == (50, 3) and np.allclose(prob.sum(axis=1), 1.0, atol=1e-5)
    label, conf = clf.predict(patches)
    assert label.dtype == np.uint8 and conf.dtype == np.float32
    assert np.allclose(conf, prob.max(axis=1))
    assert ((label == LABEL_UNKNOWN) == (conf < 0.9)).all()
    never = Classifier.load(path, threshold=1.01)
    assert (never.predict(patches)[0] == LABEL_UNKNOWN).all()
    always = Classifier.load(path, threshold=0.0)
    assert (always.predict(patches)[0] == prob.argmax(axis=1)).all()
    empty_label, empty_conf = clf.predict(np.zeros((0, 18, 18), np.uint8))
    assert empty_label.shape == (0,) and empty_conf.shape == (0,)
    with pytest.raises(ValueError, match="18"):
        clf.predict(np.zeros((4, 16, 16), np.uint8))


def test_mismatched_weights_are_refused_clearly(tmp_path):
    model = GlyphNet(3)
    cases = {
        "shape": (_blob(model, state_dict={**model.state_dict(),
                                           "fc1.weight": torch.zeros(32, 16)}),
                  r"fc1\.weight has shape \(32, 16\), expected \(32, 64\)"),
        "missing": (_blob(model, state_dict={k: v for k, v in model.state_dict().items()
                                             if k != "conv2.bias"}), "lack conv2.bias"),
        "version": (_blob(model, version=FORMAT_VERSION + 1), "format version"),
        "arch": (_blob(model, arch="resnet"), "architecture 'resnet'"),
        "format": ({"state_dict": model.state_dict()}, "not a tactile_sl_classifier"),
    }
    for name, (blob, message) in cases.items():
        path = tmp_path / f"{name}.pt"
        torch.save(blob, path)
        with pytest.raises(ClassifierError, match=message):
            Classifier.load(path)
    (tmp_path / "junk.pt").write_bytes(b"not a zip file")
    with pytest.raises(ClassifierError, match="not a loadable weights file"):
        Classifier.load(tmp_path / "junk.pt")
    with pytest.raises(ClassifierError, match="not found"):
        Classifier.load(tmp_path / "absent.pt")


def test_weights_with_code_are_not_unpickled(tmp_path):
    """weights_only loading: a pickle that would run code is rejected, not executed."""
    class Evil:
        def __reduce__(self):
            return (print, ("pwned",))

    path = tmp_path / "evil.pt"
    torch.save({"format": FORMAT, "payload": Evil()}, path)
    with pytest.raises(ClassifierError):
        Classifier.load(path)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["classifier.pt", "classifier_lenet5.pt"])
def test_shipped_weights_classify_synthetic_glyphs(name):
    """Independent renderer (not the training simulator): shipped weights still read it."""
    path = default_weights_path().with_name(name)
    assert path.is_file()
    clf = Classifier.load(path)
    assert clf.threshold == pytest.approx(DEFAULT_THRESHOLD)
    assert clf.primitives == ["line", "circle", "triangle"]
    correct = total = 0
    for seed, spacing in ((10, 15.0), (11, 20.0)):
        img = synth_image(np.random.default_rng(seed), spacing=spacing)
        det = extract_symbols(img.gray)
        idx, truth = label_detections(det, np.column_stack((img.u, img.v)), img.label)
        label, _ = clf.predict(det.patches[idx])
        correct += int((label == truth).sum())
        total += len(idx)
    assert total > 1000 and correct / total >= 0.99


def test_weights_file_is_read_without_torch_exactly(tmp_path):
    """The torch-free reader gives torch.load's tensors: views, offsets, dtypes, OrderedDict."""
    from tactile_sl_decoder.classify.weights_file import read_torch_zip

    base = torch.arange(60, dtype=torch.float32).reshape(6, 10)
    blob = {"format": FORMAT, "nested": [1, 2.5, "x", (3, None)],
            "state_dict": GlyphNet(3).state_dict(),          # an OrderedDict
            "transposed": base.t(), "offset": base[2:, 3:7], "doubles": base.double() / 7,
            "ints": torch.tensor([-3, 5], dtype=torch.int64), "flags": torch.tensor([True, False]),
            "empty": torch.zeros((0, 4))}
    path = tmp_path / "w.pt"
    torch.save(blob, path)
    ref = torch.load(path, weights_only=True)
    got = read_torch_zip(path)
    assert got["format"] == FORMAT and got["nested"] == [1, 2.5, "x", (3, None)]
    assert list(got["state_dict"]) == list(ref["state_dict"])
    for key in ("transposed", "offset", "doubles", "ints", "flags", "empty"):
        want = ref[key].numpy()
        assert got[key].dtype == want.dtype and got[key].shape == want.shape, key
        assert np.array_equal(got[key], want), key
    for key, value in ref["state_dict"].items():
        assert np.array_equal(got["state_dict"][key], value.numpy()), key


def test_truncated_weights_file_is_refused_clearly(tmp_path):
    path = tmp_path / "w.pt"
    save_blob(_blob(GlyphNet(3)), path)
    cut = tmp_path / "cut.pt"
    cut.write_bytes(path.read_bytes()[:len(path.read_bytes()) // 2])
    with pytest.raises(ClassifierError, match="not a loadable weights file"):
        Classifier.load(cut)



def test_a_layout_the_reader_does_not_know_goes_to_torch(tmp_path, monkeypatch):
    """Weights a newer torch lays out otherwise still load (through torch.load)."""
    from tactile_sl_decoder.classify import classifier as classifier_module
    from tactile_sl_decoder.classify.weights_file import WeightsFileError

    model = GlyphNet(3).eval()
    path = tmp_path / "w.pt"
    save_blob(_blob(model), path)

    def unknown(_path):
        raise WeightsFileError("refusing to unpickle torch._utils._rebuild_tensor_v9")

    monkeypatch.setattr(classifier_module, "read_torch_zip", unknown)
    clf = Classifier.load(path)
    patches = np.random.default_rng(1).integers(0, 256, (20, 18, 18), dtype=np.uint8)
    with torch.no_grad():
        ref = model(standardise(torch.from_numpy(patches))).numpy()
    assert np.abs(clf.net.logits(patches) - ref).max() < 1e-4 * max(1.0, np.abs(ref).max())


def test_corrupt_archive_entry_is_a_weights_file_error(tmp_path):
    """A bad CRC inside the archive is reported, not raised as a zipfile traceback."""
    from tactile_sl_decoder.classify.weights_file import WeightsFileError, read_torch_zip

    path = tmp_path / "w.pt"
    save_blob(_blob(GlyphNet(3)), path)
    data = bytearray(path.read_bytes())
    at = data.find(FORMAT.encode())
    data[at:at + 4] = b"XXXX"                       # inside data.pkl: its CRC no longer fits
    path.write_bytes(bytes(data))
    with pytest.raises(WeightsFileError, match="CRC"):
        read_torch_zip(path)
    with pytest.raises(ClassifierError):
        Classifier.load(path)


@pytest.mark.parametrize("content", ["random bytes", "a pickled dict", "a pickle with code",
                                     "a broken zip"])
def test_a_garbage_weights_file_gets_no_advice_to_unpickle_it(tmp_path, content, capsys):
    """Issue 28, item 14: the error repeated torch's advice to retry with
    weights_only=False, which runs the file's code: never for an untrusted file."""
    import pickle

    path = tmp_path / "garbage.pt"
    if content == "random bytes":
        path.write_bytes(np.random.default_rng(0).integers(0, 256, 3000, np.uint8).tobytes())
    elif content == "a pickled dict":
        path.write_bytes(pickle.dumps({"format": FORMAT}, protocol=4))
    elif content == "a pickle with code":
        path.write_bytes(pickle.dumps(print, protocol=2))
    else:
        path.write_bytes(b"PK\x03\x04" + bytes(200))
    with pytest.raises(ClassifierError) as info:
        Classifier.load(path)
    text = str(info.value)
    assert "not a loadable weights file" in text and str(path) in text
    assert "weights_only" not in text and "False" not in text, text
    assert "\n" not in text and len(text) < 600, text
    assert "Warning" not in capsys.readouterr().err


def _real_patches() -> np.ndarray:
    """Glyph patches of a few frames of recorded bags (bright and dark scenes)."""
    from tactile_sl_common.images import to_gray
    from tactile_sl_decoder.frames import bag_frames

    from ros_harness import REPO

    out = []
    for name in ("harsh_lighting.mcap", "robust_dark_object.mcap", "sphere_deep_small.mcap"):
        for i, frame in enumerate(bag_frames(REPO / "bags" / name, camera_info=False)):
            if i % 5 == 0:
                out += [extract_symbols(to_gray(frame.left_image)).patches,
                        extract_symbols(to_gray(frame.right_image)).patches]
            if i >= 10:
                break
    return np.concatenate(out)


def _fma_reference(net: FastTiny, patches: np.ndarray) -> np.ndarray:
    """The hidden layer as :func:`_tiny_hidden` defines it, written out independently.

    Every product sum is a chain of fused multiply-adds from 0, k ascending; a fused
    multiply-add is computed in x87 extended precision (64-bit significand: the product of
    two float32 is exact, and the sum rounds once more only where the float32 rounding
    could not tell) and rounded to float32.
    """
    ext = np.longdouble
    if np.finfo(ext).nmant < 63:
        pytest.skip("needs x87 extended precision for the reference")

    def fma(a, b, c):
        return (c.astype(ext) + a.astype(ext) * b.astype(ext)).astype(np.float32)

    x = patches.reshape(len(patches), 324).astype(np.int64)
    size = np.float32(324.0)
    mean = x.sum(axis=1).astype(np.float32) / size
    var = (x * x).sum(axis=1).astype(np.float32) / size - mean * mean
    inv = np.float32(1.0) / (np.sqrt(np.maximum(var, np.float32(0.0))) + np.float32(1.0))
    shift = mean * inv
    img = patches.astype(np.int64)
    pooled = (img[:, 0::2, 0::2] + img[:, 0::2, 1::2] + img[:, 1::2, 0::2]
              + img[:, 1::2, 1::2]).astype(np.float32)                # (n, 9, 9)
    taps = net._taps()
    channels = net.s1.shape[0]
    conv = np.zeros((len(x), 7, 7, channels), np.float32)
    for dy in range(3):
        for dx in range(3):
            conv = fma(pooled[:, dy:dy + 7, dx:dx + 7, None], taps[dy, dx], conv)
    padded = np.concatenate([conv, conv[:, -1:]], axis=1)             # ceil-mode pooling
    padded = np.concatenate([padded, padded[:, :, -1:]], axis=2)
    pooled2 = np.maximum(np.maximum(padded[:, 0::2, 0::2], padded[:, 1::2, 0::2]),
                         np.maximum(padded[:, 0::2, 1::2], padded[:, 1::2, 1::2]))
    feats = pooled2 * inv[:, None, None, None] + (net.b1 - shift[:, None, None, None] * net.s1)
    feats = np.maximum(feats, np.float32(0.0)).reshape(len(x), 16 * channels)
    hidden = np.zeros((len(x), net.w2.shape[1]), np.float32)
    for k in range(net.w2.shape[0]):
        hidden = fma(feats[:, k:k + 1], net.w2[k], hidden)
    return np.maximum(hidden + net.b2, np.float32(0.0))


def test_tiny_kernel_is_one_arithmetic_on_every_machine():
    """The default classifier's hidden layer for uint8 patches: fused multiply-adds from 0
    in ascending k, bit for bit (shipped and random weights; real, uniform, bright -- sums
    of squares past 2^24 -- and flat patches), the same bits whatever the batch (blocks of
    128 and of 512); the logits are that layer times numpy's last product, within float32
    rounding of the numpy code (whose OpenBLAS sums in an order of its CPU's)."""
    from tactile_sl_decoder.classify import classifier as classifier_module

    real = _real_patches()
    assert len(real) > 1000
    squares = (real.reshape(len(real), -1).astype(np.int64) ** 2).sum(axis=1)
    assert (squares > 2 ** 24).any()          # the sums that round in float32 occur
    rng = np.random.default_rng(7)
    bright = rng.integers(200, 256, (300, 18, 18), dtype=np.uint8)
    bright[:3] = np.array([255, 254, 0], np.uint8)[:, None, None]
    uniform = rng.integers(0, 256, (300, 18, 18), dtype=np.uint8)
    shipped = Classifier.load().net
    assert isinstance(shipped, FastTiny)
    torch.manual_seed(3)
    other = GlyphNetTiny(3, 8, 16).eval()
    with torch.no_grad():
        for p in other.parameters():
            p.mul_(3.0)
    random_net = FastTiny.from_state({k: v.numpy() for k, v in other.state_dict().items()})

    def hidden(net, patches):
        return classifier_module._tiny_hidden(
            np.ascontiguousarray(patches).reshape(len(patches), 324), net._taps(), net.s1,
            net.b1, net.w2, net.b2)

    for net in (shipped, random_net):
        for patches in (real[:400], bright, uniform):
            layer = hidden(net, patches)
            assert np.array_equal(layer, _fma_reference(net, patches))
            got = net.logits(patches)
            assert np.array_equal(got, layer @ net.w3 + net.b3)
            numpy_code = net._numpy_logits(patches)
            assert np.allclose(got, numpy_code, rtol=1e-5, atol=1e-5 * np.abs(got).max())
            for n in (2, 17, 129):
                start = int(rng.integers(0, len(patches) - n + 1))
                assert np.array_equal(hidden(net, patches[start:start + n]),
                                      layer[start:start + n]), n
        readonly = real[:600].copy()
        readonly.flags.writeable = False
        assert np.array_equal(hidden(net, readonly), np.concatenate(
            [hidden(net, real[:300]), hidden(net, real[300:600])]))


def test_tiny_runs_numpy_for_one_patch_float_patches_and_other_bands(monkeypatch):
    """uint8 batches take the kernel; one patch (numpy's gemv), float patches and a band
    of another layout take the numpy code."""
    from tactile_sl_decoder.classify import classifier as classifier_module

    net = Classifier.load().net
    patches = np.random.default_rng(2).integers(0, 256, (40, 18, 18), dtype=np.uint8)
    calls = []
    kernel = classifier_module._tiny_hidden

    def counted(*args):
        calls.append(len(args[0]))
        return kernel(*args)

    monkeypatch.setattr(classifier_module, "_tiny_hidden", counted)
    net.logits(patches)
    assert calls == [40]
    assert np.array_equal(net.logits(patches[:1]), net._numpy_logits(patches[:1]))
    assert np.array_equal(net.logits(patches.astype(np.float32)),
                          net._numpy_logits(patches)) and calls == [40]
    odd = FastTiny(net.band.copy(), net.s1, net.b1, net.w2, net.b2, net.w3, net.b3)
    odd.band[0, -1] = 0.5                      # a weight outside the 3x3 band
    assert odd._taps() is None and net._taps() is not None
    assert np.array_equal(odd.logits(patches), odd._numpy_logits(patches))
    assert calls == [40]
