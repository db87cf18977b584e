"""The decoder's health as plain status records: what it publishes on ``/diagnostics``.

No rclpy here (the thin publisher is :mod:`.diagnostics_publisher`): the node reports what
happens (a message in, a pair dropped, a frame decoded or skipped, a calibration check, the
touch reference) and :meth:`DecoderDiagnostics.statuses` turns the last period into one
:class:`Status` per task with a level OK / WARN / ERROR judged against
:class:`DiagnosticLimits`.  The tasks, figures and thresholds are documented in
docs/diagnostics.md; the levels are those of diagnostic_msgs/DiagnosticStatus.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tactile_sl_common.settings import SettingsTable, scalar_fields
from tactile_sl_decoder.calibrate.health import HealthLimits
from tactile_sl_decoder.contract import LABEL_UNKNOWN
from tactile_sl_decoder.touch.reference import RESIDUAL_WARN_M, residual_warning

OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR", STALE: "STALE"}


@dataclass
class DiagnosticLimits:
    """Thresholds of the OK / WARN / ERROR levels (docs/diagnostics.md)."""

    input_timeout_s: float = 2.0
    """Seconds without a message on a camera input before its status is ERROR."""
    drop_warn: float = 0.1
    """Fraction of a camera's messages of the period dropped unpaired above which: WARN."""
    drop_error: float = 0.5
    """Fraction of a camera's messages of the period dropped unpaired above which: ERROR."""
    latency_warn_s: float = 0.5
    """Median stamp-to-output latency of the period above which: WARN, seconds."""
    latency_error_s: float = 2.0
    """Median stamp-to-output latency of the period above which: ERROR, seconds."""
    stamp_live_s: float = 60.0
    """Latencies beyond this (or below -1 s) mean the stamps are not live time (a bag played
    without restamp, another clock): latency is then reported but not judged, seconds."""
    min_glyphs: float = 50.0
    """Mean glyphs found per image below which: WARN (pad out of view, dark, out of focus)."""
    coverage_warn: float = 0.5
    """Mean share of the glyphs found that became cells decoded in both images, below which:
    WARN."""
    coverage_error: float = 0.1
    """The same share below which: ERROR (wrong pattern file, mirrored or calibration)."""
    unknown_warn: float = 0.2
    """Share of glyphs the classifier left unknown (below its threshold) above which: WARN."""
    unknown_error: float = 0.6
    """Share of unknown glyphs above which: ERROR (wrong weights, blur, wrong exposure)."""
    confidence_warn: float = 0.8
    """Mean classifier confidence below which: WARN."""
    assisted_warn: float = 0.05
    """Share of the points whose cell one image got from the other camera (that camera
    found the glyph but could not read it, or did not find it) above which: WARN naming the
    camera (a dirty lens, a dark corner, a shadow on one side)."""
    reference_residual_warn_m: float = RESIDUAL_WARN_M
    """RMS residual of the pad-frame fit of the touch reference above which: WARN, metres
    (the pad was touched or bent when the reference was taken)."""
    calibration_error_factor: float = 3.0
    """A calibration health figure beyond this multiple of its limit: ERROR (beyond the
    limit itself: WARN)."""


DIAGNOSTIC_SETTINGS = SettingsTable(DiagnosticLimits, ranges={
    name: (0.0, 1e6) for name in scalar_fields(DiagnosticLimits)})
"""The decoder node's live ``diagnostics.<field>`` parameters."""


@dataclass
class Status:
    """One task's status: what diagnostic_msgs/DiagnosticStatus carries."""

    name: str
    level: int
    message: str
    values: dict[str, str] = field(default_factory=dict)

    @property
    def level_name(self) -> str:
        return LEVEL_NAMES.get(self.level, str(self.level))


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    return str(value)


@dataclass
class _Side:
    messages: int = 0            # total
    period_messages: int = 0
    period_dropped: int = 0
    dropped: int = 0             # total
    last_s: float | None = None  # monotonic time of the last message
    period_first_s: float | None = None
    info: bool = False           # a CameraInfo arrived


@dataclass
class _Frames:
    decoded: int = 0
    skipped: int = 0
    last_skip: str = ""
    proc_s: list[float] = field(default_factory=list)
    latency_s: list[float] = field(default_factory=list)
    glyphs: list[int] = field(default_factory=list)      # per image
    cells: list[int] = field(default_factory=list)       # per image, decoded
    points: list[int] = field(default_factory=list)      # per frame
    coverage: list[float] = field(default_factory=list)  # per frame
    rejected: int = 0
    assisted: list[int] = field(default_factory=lambda: [0, 0])   # left, right, summed
    confidence_sum: float = 0.0
    labelled: int = 0
    unknown: int = 0


class DecoderDiagnostics:
    """Collects what the decoder does during a period and judges it once per period."""

    def __init__(self, limits: DiagnosticLimits | None = None, now_s: float = 0.0) -> None:
        self.limits = limits or DiagnosticLimits()
        self.sides = {"left": _Side(), "right": _Side()}
        self.period = _Frames()
        self.totals = {"decoded": 0, "skipped": 0}
        self.period_start = now_s
        self.calibration: Status = Status("calibration", WARN,
                                          "not checked yet: waiting for a frame of the "
                                          "untouched pad decoded in both images")
        self.touch: Status = Status("touch reference", OK, "touch outputs off")

    # ------------------------------------------------------------ events

    def message(self, side: str, now_s: float) -> None:
        """An image (or SymbolArray) arrived on ``side``."""
        s = self.sides[side]
        s.messages += 1
        s.period_messages += 1
        s.last_s = now_s
        if s.period_first_s is None:
            s.period_first_s = now_s

    def camera_info(self, side: str) -> None:
        self.sides[side].info = True

    def dropped(self, side: str) -> None:
        """A message of ``side`` was dropped without its stereo partner."""
        s = self.sides[side]
        s.dropped += 1
        s.period_dropped += 1

    def skipped(self, reason: str) -> None:
        """A stereo frame was skipped (bad input); ``reason`` is the warning's text."""
        self.period.skipped += 1
        self.totals["skipped"] += 1
        self.period.last_skip = reason

    def frame(self, proc_s: float, latency_s: float, left: Any, right: Any, points: int,
              rejected: int = 0, assisted: tuple[int, int] = (0, 0)) -> None:
        """A frame went through the pipeline; ``left``/``right`` are its Glyphs.

        ``assisted``: cells of the left / right image that came from the other camera.
        """
        p = self.period
        p.decoded += 1
        self.totals["decoded"] += 1
        p.proc_s.append(float(proc_s))
        p.latency_s.append(float(latency_s))
        p.points.append(int(points))
        p.rejected += int(rejected)
        p.assisted[0] += int(assisted[0])
        p.assisted[1] += int(assisted[1])
        found = []
        for g in (left, right):
            n = len(g)
            found.append(n)
            p.glyphs.append(n)
            p.cells.append(int(np.count_nonzero(np.asarray(g.row) >= 0)) if n else 0)
            if n:
                label = np.asarray(g.label)
                p.labelled += n
                p.unknown += int(np.count_nonzero(label == LABEL_UNKNOWN))
                p.confidence_sum += float(np.sum(np.asarray(g.confidence, np.float64)))
        if min(found) > 0:
            p.coverage.append(points / min(found))

    def calibration_checked(self, report: Any) -> Status:
        """Judge a :class:`~tactile_sl_decoder.calibrate.health.HealthReport`; keep it."""
        self.calibration = calibration_status(report, self.limits)
        return self.calibration

    def calibration_waiting(self, why: str) -> None:
        self.calibration = Status("calibration", WARN, f"not checked yet: {why}")

    def touch_state(self, enabled: bool, ready: bool = False, frames_needed: int = 1,
                    cells: int = 0, residual_rms_m: float = float("nan"),
                    residual_max_m: float = float("nan"), tares: int = 0,
                    last_tare: str = "", preparing: bool = False, pending: int = 0,
                    pending_dropped: int = 0) -> None:
        """The touch reference and tare state, as the touch outputs see it now.

        ``pending``: frames waiting for the reference being prepared (their outputs follow);
        ``pending_dropped``: frames that found that queue full (no touch outputs).
        """
        values = {"enabled": _fmt(enabled), "reference": _fmt(ready), "tares": _fmt(tares),
                  "last_tare": last_tare or "none", "preparing": _fmt(preparing),
                  "frames_waiting": _fmt(pending), "frames_without_touch": _fmt(pending_dropped)}
        if not enabled:
            self.touch = Status("touch reference", OK, "touch outputs off", values)
            return
        if not ready and preparing:
            self.touch = Status("touch reference", WARN, "preparing the reference (pad pose, "
                                f"inversion) in the background; {pending} frame(s) wait for "
                                "their touch outputs", values)
            return
        if not ready:
            self.touch = Status("touch reference", WARN,
                                f"waiting for the reference: {frames_needed} decoded frame(s) "
                                "of the untouched pad", values)
            return
        values.update(cells=_fmt(cells), residual_rms_um=_fmt(residual_rms_m * 1e6),
                      residual_max_um=_fmt(residual_max_m * 1e6))
        warning = residual_warning(residual_rms_m, self.limits.reference_residual_warn_m)
        if warning is not None:
            self.touch = Status("touch reference", WARN,
                                f"reference of {cells} cells, {warning}", values)
        else:
            self.touch = Status("touch reference", OK, f"reference of {cells} cells, pad fit "
                                f"residual {residual_rms_m * 1e6:.1f} um RMS", values)

    # ------------------------------------------------------------ judgement

    def statuses(self, now_s: float) -> list[Status]:
        """One status per task for the period ending now; starts the next period."""
        span = max(now_s - self.period_start, 1e-3)
        out = [self._input(side, now_s, span) for side in ("left", "right")]
        out += [self._processing(span), self._coverage(), self._classifier(),
                self.touch, self.calibration]
        self.period = _Frames()
        for s in self.sides.values():
            s.period_messages = s.period_dropped = 0
            s.period_first_s = None
        self.period_start = now_s
        return out

    def rate(self, side: str, span: float) -> float:
        """Messages per second of ``side`` in the period.

        From the first to the last arrival when there were at least three (a short period
        holds few frames), else count / period.
        """
        s = self.sides[side]
        if s.period_messages >= 3 and s.last_s is not None and s.period_first_s is not None \
                and s.last_s > s.period_first_s:
            return (s.period_messages - 1) / (s.last_s - s.period_first_s)
        return s.period_messages / span

    def _input(self, side: str, now_s: float, span: float) -> Status:
        lim, s = self.limits, self.sides[side]
        name = f"input {side}"
        rate = self.rate(side, span)
        values = {"rate_hz": _fmt(rate), "messages": _fmt(s.messages),
                  "dropped_unpaired": _fmt(s.dropped),
                  "dropped_unpaired_period": _fmt(s.period_dropped),
                  "camera_info": _fmt(s.info)}
        if s.last_s is None:
            return Status(name, WARN, f"waiting for {side} images", values)
        age = now_s - s.last_s
        values["last_message_age_s"] = _fmt(age)
        if age > lim.input_timeout_s:
            return Status(name, ERROR, f"no {side} image for {age:.1f} s", values)
        share = s.period_dropped / max(s.period_messages, 1)
        text = f"{rate:.1f} Hz"
        if share > lim.drop_error:
            return Status(name, ERROR, f"{text}, {100 * share:.0f} % dropped without a stereo "
                          "partner (stamps of left and right differ? see sync_slop)", values)
        if share > lim.drop_warn:
            return Status(name, WARN, f"{text}, {100 * share:.0f} % dropped without a stereo "
                          "partner", values)
        if not s.info:
            return Status(name, WARN, f"{text}, no {side}/camera_info yet: frames are skipped",
                          values)
        return Status(name, OK, text, values)

    def _processing(self, span: float) -> Status:
        lim, p = self.limits, self.period
        values = {"frames_decoded": _fmt(p.decoded), "frames_skipped": _fmt(p.skipped),
                  "frames_decoded_total": _fmt(self.totals["decoded"]),
                  "frames_skipped_total": _fmt(self.totals["skipped"])}
        if p.proc_s:
            proc = np.asarray(p.proc_s) * 1e3
            lat = np.asarray(p.latency_s)
            values.update(processing_median_ms=_fmt(float(np.median(proc))),
                          processing_max_ms=_fmt(float(proc.max())),
                          latency_median_ms=_fmt(float(np.median(lat)) * 1e3),
                          latency_max_ms=_fmt(float(lat.max()) * 1e3))
        name = "processing"
        if p.decoded == 0 and p.skipped == 0:
            return Status(name, OK, "no frame in the last period", values)
        if p.decoded == 0:
            return Status(name, ERROR, f"every frame skipped ({p.skipped}): {p.last_skip}",
                          values)
        proc_ms = float(np.median(np.asarray(p.proc_s))) * 1e3
        median_lat = float(np.median(np.asarray(p.latency_s)))
        text = (f"{p.decoded} frame(s), {proc_ms:.0f} ms median processing, "
                f"latency {median_lat * 1e3:.0f} ms")
        level, notes = OK, []
        if p.skipped:
            level = WARN
            notes.append(f"{p.skipped} skipped: {p.last_skip}")
        if median_lat > lim.stamp_live_s or median_lat < -1.0:
            notes.append("stamps are not live time (bag without restamp?): latency not judged")
            values["latency_judged"] = "false"
        elif median_lat > lim.latency_error_s:
            level = ERROR
            notes.append(f"latency above {lim.latency_error_s:g} s")
        elif median_lat > lim.latency_warn_s:
            level = max(level, WARN)
            notes.append(f"latency above {lim.latency_warn_s:g} s")
        rate = min(self.rate(s, span) for s in ("left", "right"))
        if rate > 0 and proc_ms * 1e-3 > 1.0 / rate:
            level = max(level, WARN)
            notes.append(f"processing slower than the input ({rate:.1f} Hz): frames are "
                         "replaced by newer ones")
        return Status(name, level, "; ".join([text, *notes]), values)

    def _coverage(self) -> Status:
        lim, p = self.limits, self.period
        name = "coverage"
        if not p.points:
            return Status(name, OK, "no frame in the last period")
        glyphs = float(np.mean(p.glyphs))
        points = float(np.mean(p.points))
        coverage = float(np.mean(p.coverage)) if p.coverage else 0.0
        values = {"glyphs_per_image": _fmt(glyphs), "cells_per_image": _fmt(float(
            np.mean(p.cells))), "points_per_frame": _fmt(points), "coverage": _fmt(coverage),
            "rejected_pairs": _fmt(p.rejected),
            "from_right_camera_in_left": _fmt(p.assisted[0] / len(p.points)),
            "from_left_camera_in_right": _fmt(p.assisted[1] / len(p.points))}
        text = (f"{points:.0f} cells decoded in both images of {glyphs:.0f} glyphs per image "
                f"({100 * coverage:.0f} %)")
        total = max(float(np.sum(p.points)), 1.0)
        share = [a / total for a in p.assisted]
        if glyphs < lim.min_glyphs:
            return Status(name, WARN, f"{text}: few glyphs found (pad out of view, too dark, "
                          "out of focus?)", values)
        if coverage < lim.coverage_error:
            return Status(name, ERROR, f"{text}: check pattern_file (is it the printed "
                          "pattern?), mirrored and the calibration", values)
        if coverage < lim.coverage_warn:
            return Status(name, WARN, f"{text}: low coverage", values)
        side = int(np.argmax(share))
        if share[side] > lim.assisted_warn:
            camera, other = ("left", "right") if side == 0 else ("right", "left")
            return Status(name, WARN, f"{text}; {100 * share[side]:.0f} % of the points "
                          f"needed the {other} camera's cells: the {camera} camera sees part "
                          "of the pad poorly (dirty lens, dark corner, shadow?)", values)
        return Status(name, OK, text, values)

    def _classifier(self) -> Status:
        lim, p = self.limits, self.period
        name = "classifier"
        if not p.labelled:
            return Status(name, OK, "no glyph in the last period")
        unknown = p.unknown / p.labelled
        conf = p.confidence_sum / p.labelled
        values = {"mean_confidence": _fmt(conf), "unknown_share": _fmt(unknown),
                  "glyphs": _fmt(p.labelled)}
        text = f"mean confidence {conf:.3f}, {100 * unknown:.1f} % unknown"
        if unknown > lim.unknown_error:
            return Status(name, ERROR, f"{text}: wrong weights, blur or exposure?", values)
        if unknown > lim.unknown_warn or conf < lim.confidence_warn:
            return Status(name, WARN, text, values)
        return Status(name, OK, text, values)


def calibration_status(report: Any, limits: DiagnosticLimits,
                       health_limits: Any = None) -> Status:
    """The calibration status of a health report.

    OK when it passes; WARN past a limit; ERROR past ``calibration_error_factor`` x a limit,
    for swapped files, or for a pad triangulated behind the cameras.
    """
    if health_limits is None:
        health_limits = HealthLimits()
    values = {k: _fmt(v) for k, v in report.as_dict().items()}
    figures = (f"residual {report.reprojection_rms_px:.3f} px, flatness "
               f"{report.flatness_rms_m * 1e6:.2f} um, pitch {100 * report.pitch_error:+.3f} %, "
               f"{report.points} cells")
    if report.ok:
        return Status("calibration", OK, f"PASS: {figures}", values)
    k = limits.calibration_error_factor
    severe = (
        report.behind > 0.05 * max(report.points, 1)
        or any("swapped" in p for p in report.problems)
        or not report.reprojection_rms_px <= k * health_limits.max_reprojection_px
        or not report.flatness_rms_m <= k * health_limits.max_flatness_m
        or not abs(report.pitch_error) <= k * health_limits.max_pitch_error)
    return Status("calibration", ERROR if severe else WARN,
                  f"FAIL: {'; '.join(report.problems)}", values)
