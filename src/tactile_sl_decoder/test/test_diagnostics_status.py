"""The decoder's status builder (no rclpy): levels against the documented thresholds."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tactile_sl_decoder.calibrate.health import HealthReport
from tactile_sl_decoder.nodes.diagnostics import (
    ERROR,
    OK,
    WARN,
    DecoderDiagnostics,
    calibration_status,
)


@dataclass
class FakeGlyphs:
    n: int
    decoded: int
    unknown: int = 0
    confidence: np.ndarray = field(default=None)

    def __post_init__(self):
        self.row = np.r_[np.zeros(self.decoded), -np.ones(self.n - self.decoded)]
        self.label = np.r_[np.full(self.n - self.unknown, 1), np.full(self.unknown, 255)]
        if self.confidence is None:
            self.confidence = np.full(self.n, 0.98)

    def __len__(self):
        return self.n


def _by_task(statuses):
    return {s.name: s for s in statuses}


def _run(frames, drops=0, points=700, glyphs=(746, 746), latency=0.05, unknown=0,
         now=1.0):
    d = DecoderDiagnostics(now_s=0.0)
    for side in ("left", "right"):
        d.camera_info(side)
    for i in range(frames):
        for side in ("left", "right"):
            d.message(side, now * (i + 1) / (frames + 1))
        d.frame(0.02, latency, FakeGlyphs(glyphs[0], glyphs[0], unknown),
                FakeGlyphs(glyphs[1], glyphs[1], unknown), points)
    for _ in range(drops):
        d.dropped("left")
    return _by_task(d.statuses(now)), d


def test_waiting_then_ok():
    d = DecoderDiagnostics(now_s=0.0)
    s = _by_task(d.statuses(1.0))
    assert s["input left"].level == WARN and "waiting" in s["input left"].message
    assert s["calibration"].level == WARN and s["processing"].level == OK
    s, _ = _run(10)
    assert all(s[k].level == OK for k in ("input left", "input right", "processing",
                                          "coverage", "classifier")), s
    assert abs(float(s["input left"].values["rate_hz"]) - 11.0) < 0.5


def test_input_stopped_and_drops():
    s, d = _run(10, drops=2)
    assert s["input left"].level == WARN and s["input right"].level == OK
    s, d = _run(10, drops=6)
    assert s["input left"].level == ERROR
    s = _by_task(d.statuses(10.0))      # nothing for 9 s
    assert s["input left"].level == ERROR and "no left image" in s["input left"].message


def test_processing_latency_and_skips():
    s, _ = _run(5, latency=1.0)
    assert s["processing"].level == WARN
    s, _ = _run(5, latency=3.0)
    assert s["processing"].level == ERROR
    s, _ = _run(5, latency=1e6)       # a bag's old stamps: reported, not judged
    assert s["processing"].level == OK and "not live" in s["processing"].message
    d = DecoderDiagnostics(now_s=0.0)
    d.skipped("no CameraInfo received yet on left/camera_info")
    s = _by_task(d.statuses(1.0))
    assert s["processing"].level == ERROR and "CameraInfo" in s["processing"].message


def test_coverage_and_classifier():
    s, _ = _run(3, points=300)
    assert s["coverage"].level == WARN
    s, _ = _run(3, points=0)
    assert s["coverage"].level == ERROR and "mirrored" in s["coverage"].message
    s, _ = _run(3, points=10, glyphs=(20, 20))
    assert s["coverage"].level == WARN and "few glyphs" in s["coverage"].message
    s, _ = _run(3, unknown=300)
    assert s["classifier"].level == WARN
    s, _ = _run(3, unknown=600)
    assert s["classifier"].level == ERROR


def test_a_camera_that_needs_the_other_ones_cells_is_named():
    """Cells one image got from the other camera (transfer, rescue): above 5 % of the
    points the coverage status warns and names the camera that sees poorly."""
    for assisted, level, camera in (((0, 0), OK, None), ((10, 0), OK, None),
                                    ((0, 50), WARN, "right"), ((60, 5), WARN, "left")):
        d = DecoderDiagnostics(now_s=0.0)
        for _ in range(3):
            d.frame(0.02, 0.05, FakeGlyphs(746, 746), FakeGlyphs(746, 746), 700,
                    assisted=assisted)
        s = _by_task(d.statuses(1.0))["coverage"]
        assert s.level == level, (assisted, s.message)
        if camera:
            assert f"the {camera} camera sees part of the pad poorly" in s.message
        assert float(s.values["from_left_camera_in_right"]) == assisted[1]
        assert float(s.values["from_right_camera_in_left"]) == assisted[0]


def test_touch_reference_state():
    d = DecoderDiagnostics()
    d.touch_state(True, False, frames_needed=2)
    assert d.touch.level == WARN and "waiting" in d.touch.message
    d.touch_state(True, False, frames_needed=2, preparing=True)
    assert d.touch.level == WARN and "preparing" in d.touch.message
    assert d.touch.values["preparing"] == "True"
    d.touch_state(True, True, 1, 700, 3e-6, 1e-5, tares=1, last_tare="accepted: ok")
    assert d.touch.level == OK and d.touch.values["tares"] == "1"
    d.touch_state(True, True, 1, 700, 5e-5, 1e-4)
    assert d.touch.level == WARN
    d.touch_state(False)
    assert d.touch.level == OK


def _report(problems=(), **figures):
    r = HealthReport(700, reprojection_rms_px=0.02, flatness_rms_m=2e-7, pitch_error=1e-4)
    for k, v in figures.items():
        setattr(r, k, v)
    r.problems = list(problems)
    return r


def test_calibration_levels():
    d = DecoderDiagnostics()
    assert calibration_status(_report(), d.limits).level == OK
    warn = _report(["reprojection residual"], reprojection_rms_px=0.3)
    assert calibration_status(warn, d.limits).level == WARN
    error = _report(["reprojection residual"], reprojection_rms_px=1.1)
    assert calibration_status(error, d.limits).level == ERROR
    swapped = _report(["left and right files are swapped"], reprojection_rms_px=float("inf"))
    assert calibration_status(swapped, d.limits).level == ERROR
