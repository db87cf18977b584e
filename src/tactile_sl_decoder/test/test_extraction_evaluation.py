"""Evaluation figures: matching rules on hand-made cases, projection, and a bundled bag."""

import numpy as np
import pytest

from tactile_sl_decoder.tooling.evaluation import (
    ImageSymbolMetrics,
    aggregate,
    classification_section,
    confusion_section,
    evaluate_symbols_bag,
    extraction_section,
    format_confusion,
    format_table,
    project_truth,
    score_image,
)

from ros_harness import REPO


def test_score_image_counts():
    gy, gx = np.mgrid[2:8, 2:10]
    truth = np.column_stack([gx.ravel() * 20.0, gy.ravel() * 20.0])  # 48 glyphs
    labels_true = (np.arange(len(truth)) % 3).astype(np.uint8)
    u = truth[:, 0].copy()
    v = truth[:, 1].copy()
    u[0] += 8.0  # 0.4 spacing off: not found, and spurious
    pred = labels_true.copy()
    pred[1] = (pred[1] + 1) % 3  # wrong
    pred[2] = 255  # unknown
    u = np.append(u, [300.0, 90.0])  # one far outside the region, one inside between glyphs
    v = np.append(v, [400.0, 50.0])
    pred = np.append(pred, [0, 0]).astype(np.uint8)
    m = ImageSymbolMetrics("s", 0, "left")
    score_image(u, v, 20.0, truth, labels_true, pred, (480, 640), 3, m)
    assert (m.truth, m.detections, m.found) == (48, 50, 47)
    assert m.outside == 1 and m.in_region == 49 and m.spurious == 2
    assert m.matched == 47 and m.correct == 45 and m.unknown == 1
    assert m.recall == pytest.approx(47 / 48)
    assert m.accuracy == pytest.approx(45 / 47)
    assert m.confident_accuracy == pytest.approx(45 / 46)
    conf = np.array(m.confusion)
    assert conf.shape == (3, 4) and conf.sum() == 47 and conf[:, 3].sum() == 1
    total = aggregate([m, m], "s")
    assert total.truth == 96 and np.array(total.confusion).sum() == 94
    text = format_table(extraction_section([m, total])) + format_table(
        classification_section([m])) + format_confusion(confusion_section(total, ["a", "b", "c"]))
    assert "recall_%" in text and "unknown" in text


def test_project_truth_identity_rig():
    from tactile_sl_common.camera_info import CameraCalibration

    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    left = CameraCalibration(640, 480, K, np.zeros(5), np.eye(3), np.hstack([K, np.zeros((3, 1))]))
    right = CameraCalibration(640, 480, K, np.zeros(5), np.eye(3),
                              np.hstack([K, [[-500.0 * 0.01], [0], [0]]]))
    xyz = np.array([[0.0, 0.0, 0.02], [0.001, -0.002, 0.015]])
    pl, pr = project_truth(xyz, left, right)
    assert np.allclose(pl[0], [320, 240]) and np.allclose(pr[0], [320 - 500 * 0.01 / 0.02, 240])
    assert np.allclose(pl[1], [320 + 500 * 0.001 / 0.015, 240 - 500 * 0.002 / 0.015])


def test_bundled_bag_extraction_figures():
    bag = REPO / "bags" / "no_contact.mcap"
    if not bag.is_file():
        pytest.skip("bundled bags not present")
    from tactile_sl_decoder.classify.classifier import Classifier

    values = np.zeros((200, 200), np.uint8)  # labels do not matter for extraction figures
    rows = evaluate_symbols_bag(bag, values, Classifier.load(), max_frames=1)
    assert [r.camera for r in rows] == ["left", "right"]
    for r in rows:
        assert r.truth > 500 and r.recall >= 0.98 and r.spurious_rate <= 0.01
        assert r.matched >= 0.98 * r.truth
