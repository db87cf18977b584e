"""Slip figures against the simulator's ground truth: state, stick ratio, margin, mu, direction.

Tooling for ``tools/bench_touch.py`` and ``tactile-sl evaluate``; the touch stage never
imports it.  One frame pairs the stage's
:class:`~tactile_sl_decoder.touch.slip.SlipEstimate` with the truth's
:class:`~tactile_sl_sim.friction.ContactSlip` (from ``ground_truth/slip``), both
carried by a :class:`~tactile_sl_decoder.tooling.touch_metrics.TouchFrameMetrics`.
The acceptance of issue 24 (docs/slip.md, "Accuracy"):

* every frame in gross slip is reported as gross, and no frame whose margin is >= 0.3;
* slip margin error: median <= 0.10 and max <= 0.25 over the loaded frames (truth in
  contact); stick ratio error: median <= 0.10 over the partial-slip frames;
* friction coefficient within 10 % (median) and 20 % (max) over the frames whose margin is
  <= 0.5 (gross slip included).

A NaN estimate where a number is due counts as an infinite error.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from tactile_sl_decoder.contract import SLIP_GROSS, SLIP_NO_CONTACT, SLIP_PARTIAL
from tactile_sl_decoder.touch.slip import STATE_NAMES

NAN = float("nan")
INF = float("inf")


@dataclass(frozen=True)
class SlipLimits:
    """Issue 24's acceptance limits."""

    margin_median: float = 0.10
    margin_max: float = 0.25
    stick_median: float = 0.10
    mu_median: float = 0.10          # relative
    mu_max: float = 0.20             # relative
    mu_frames_margin: float = 0.5    # mu is judged on frames whose true margin is <= this
    never_gross_margin: float = 0.3  # no frame with a true margin >= this may read gross


LIMITS = SlipLimits()


@dataclass
class SlipFrame:
    """Truth and estimate of one frame's slip."""

    scene: str
    stamp_ns: int
    true: Any                     # ContactSlip
    est: Any                      # SlipEstimate (None: the stage gave no output)
    slip_ms: float = NAN

    @property
    def loaded(self) -> bool:
        """The truth is in contact (a normal load presses)."""
        return self.true.state != SLIP_NO_CONTACT

    def _est(self, name: str) -> float:
        return NAN if self.est is None else float(getattr(self.est, name))

    @property
    def margin_err(self) -> float:
        """|estimate - truth| of the slip margin (inf for a NaN estimate)."""
        return _abs_err(self._est("margin"), float(self.true.margin))

    @property
    def stick_err(self) -> float:
        return _abs_err(self._est("stick_ratio"), float(self.true.stick_ratio))

    @property
    def mu_err(self) -> float:
        """Relative error of the friction coefficient (inf for a NaN estimate)."""
        true = float(self.true.friction)
        return _abs_err(self._est("friction"), true) / true if true > 0 else NAN

    @property
    def direction_err_deg(self) -> float:
        """Angle between the true and estimated slip directions (NaN without tangential load)."""
        t = np.asarray(self.true.direction[:2], np.float64)
        e = np.zeros(2) if self.est is None else np.asarray(self.est.direction[:2], np.float64)
        if not np.any(t) or not np.any(e):
            return NAN
        c = float(np.dot(t, e) / (np.linalg.norm(t) * np.linalg.norm(e)))
        return math.degrees(math.acos(min(max(c, -1.0), 1.0)))

    @property
    def state_est(self) -> int:
        return SLIP_NO_CONTACT if self.est is None else int(self.est.state)


def _abs_err(est: float, true: float) -> float:
    if not math.isfinite(true):
        return NAN
    return abs(est - true) if math.isfinite(est) else INF


def slip_frames(touch_frames: Iterable[Any]) -> list[SlipFrame]:
    """The frames of ``TouchFrameMetrics`` that carry slip truth."""
    return [SlipFrame(f.bag, f.stamp_ns, f.slip_true, f.slip_est if f.output else None,
                      float(f.timings_ms.get("slip", NAN)))
            for f in touch_frames if f.slip_true is not None]


def acceptance(frames: list[SlipFrame], limits: SlipLimits = LIMITS) -> dict[str, Any]:
    """Issue 24's figures over ``frames`` and whether each meets its limit."""
    loaded = [f for f in frames if f.loaded]
    partial = [f for f in loaded if f.true.state == SLIP_PARTIAL]
    mu_frames = [f for f in loaded if f.true.margin <= limits.mu_frames_margin]
    gross = [f for f in loaded if f.true.state == SLIP_GROSS]
    not_gross = [f for f in loaded if f.true.margin >= limits.never_gross_margin]

    def stats(values: list[float]) -> tuple[float, float]:
        v = np.asarray([x for x in values if not math.isnan(x)], np.float64)
        return (float(np.median(v)), float(v.max())) if len(v) else (NAN, NAN)

    margin_med, margin_max = stats([f.margin_err for f in loaded])
    stick_med, stick_max = stats([f.stick_err for f in partial])
    mu_med, mu_max = stats([f.mu_err for f in mu_frames])
    dir_med, dir_max = stats([f.direction_err_deg for f in loaded])
    gross_hit = sum(f.state_est == SLIP_GROSS for f in gross)
    false_gross = sum(f.state_est == SLIP_GROSS for f in not_gross)
    out = {
        "frames": len(frames), "loaded": len(loaded), "partial": len(partial),
        "mu_frames": len(mu_frames), "gross": len(gross), "gross_reported": gross_hit,
        "margin_ge_limit": len(not_gross), "false_gross": false_gross,
        "margin_err_median": margin_med, "margin_err_max": margin_max,
        "stick_err_median": stick_med, "stick_err_max": stick_max,
        "mu_err_median": mu_med, "mu_err_max": mu_max,
        "direction_err_median_deg": dir_med, "direction_err_max_deg": dir_max,
        "state_agree": sum(f.state_est == f.true.state for f in frames),
    }
    out["pass"] = {
        "gross": gross_hit == len(gross) and false_gross == 0,
        "margin": margin_med <= limits.margin_median and margin_max <= limits.margin_max,
        "stick_ratio": not partial or stick_med <= limits.stick_median,
        "friction": not mu_frames or (mu_med <= limits.mu_median and mu_max <= limits.mu_max),
    }
    return out


# ---------------------------------------------------------------------- tables


def _f(v: float, fmt: str, width: int) -> str:
    return f"{'-':>{width}}" if v is None or not math.isfinite(v) else f"{format(v, fmt):>{width}}"


SLIP_HEADER = (f"{'scene':<20} {'t s':>4} {'state t/e':>15} {'stick t':>7} {'e':>6} "
               f"{'margin t':>8} {'e':>6} {'|dm|':>5} {'mu t':>5} {'e':>6} {'dmu%':>6} "
               f"{'dir':>5} {'rms':>5} {'ms':>5}")
SLIP_UNITS = (f"{'':<20} {'':>4} {'':>15} {'':>7} {'':>6} {'':>8} {'':>6} {'':>5} {'':>5} "
              f"{'':>6} {'':>6} {'deg':>5} {'um':>5} {'':>5}")


def format_slip_frame(f: SlipFrame, t0_ns: int = 0) -> str:
    """One table row: truth and estimate of a frame (errors are estimate - truth)."""
    est = f.est
    states = f"{STATE_NAMES.get(f.true.state, '?')}/{STATE_NAMES.get(f.state_est, '?')}"
    mu_err = (float(est.friction) - f.true.friction) / f.true.friction \
        if est is not None and f.true.friction > 0 else NAN
    return (f"{f.scene:<20} {(f.stamp_ns - t0_ns) / 1e9:>4.1f} {states:>15} "
            f"{_f(f.true.stick_ratio, '.3f', 7)} {_f(f._est('stick_ratio'), '.3f', 6)} "
            f"{_f(f.true.margin, '.3f', 8)} {_f(f._est('margin'), '.3f', 6)} "
            f"{_f(f.margin_err, '.3f', 5)} {_f(f.true.friction, '.2f', 5)} "
            f"{_f(f._est('friction'), '.3f', 6)} {_f(100 * mu_err, '+.1f', 6)} "
            f"{_f(f.direction_err_deg, '.1f', 5)} {_f(1e6 * f._est('fit_residual'), '.1f', 5)} "
            f"{_f(f.slip_ms, '.2f', 5)}")


def format_acceptance(fig: dict[str, Any], limits: SlipLimits = LIMITS) -> str:
    """The acceptance figures, one line each, with their limits and PASS / FAIL."""
    ok = fig["pass"]

    def verdict(key: str) -> str:
        return "pass" if ok[key] else "FAIL"

    return "\n".join([
        f"gross slip: {fig['gross_reported']}/{fig['gross']} gross frames reported gross; "
        f"{fig['false_gross']} of {fig['margin_ge_limit']} frames with margin >= "
        f"{limits.never_gross_margin} reported gross ({verdict('gross')})",
        f"slip margin |error| over {fig['loaded']} loaded frames: median "
        f"{fig['margin_err_median']:.3f} (<= {limits.margin_median}), max "
        f"{fig['margin_err_max']:.3f} (<= {limits.margin_max}) ({verdict('margin')})",
        f"stick ratio |error| over {fig['partial']} partial-slip frames: median "
        f"{fig['stick_err_median']:.3f} (<= {limits.stick_median}), max "
        f"{fig['stick_err_max']:.3f} ({verdict('stick_ratio')})",
        f"friction coefficient |error| over {fig['mu_frames']} frames with margin <= "
        f"{limits.mu_frames_margin}: median {100 * fig['mu_err_median']:.1f} % "
        f"(<= {100 * limits.mu_median:.0f} %), max {100 * fig['mu_err_max']:.1f} % "
        f"(<= {100 * limits.mu_max:.0f} %) ({verdict('friction')})",
        f"slip direction error: median {fig['direction_err_median_deg']:.1f} deg, max "
        f"{fig['direction_err_max_deg']:.1f} deg; state agrees on {fig['state_agree']}/"
        f"{fig['frames']} frames (a thin slip annulus, margin > ~0.7, reads stick)",
    ])


def format_slip_report(per_scene: list[tuple[str, list[SlipFrame]]]) -> str:
    """Per-frame table of every scene, then the acceptance figures over all of them."""
    lines = [SLIP_HEADER, SLIP_UNITS]
    every: list[SlipFrame] = []
    for _name, frames in per_scene:
        if not frames:
            continue
        t0 = min(f.stamp_ns for f in frames)
        lines += [format_slip_frame(f, t0) for f in frames]
        every += frames
    lines.append("")
    lines.append(format_acceptance(acceptance(every)))
    return "\n".join(lines)
