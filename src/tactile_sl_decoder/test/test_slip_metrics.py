"""Slip figures against the truth: issue 24's acceptance computed as documented."""
import math

import pytest

from tactile_sl_decoder.contract import SLIP_GROSS, SLIP_PARTIAL, SLIP_STICK
from tactile_sl_decoder.tooling.slip_metrics import (
    SlipFrame,
    acceptance,
    format_slip_report,
)
from tactile_sl_decoder.touch.slip import SlipEstimate
from tactile_sl_sim.friction import cattaneo_mindlin


def _frame(ratio: float, state: int, margin: float, friction: float, stamp: int = 0,
           direction: tuple[float, float, float] = (1.0, 0.0, 0.0)) -> SlipFrame:
    true = cattaneo_mindlin((ratio * 0.25, 0.0, -0.5), 0.5, 0.003)
    stick = margin ** (2.0 / 3.0) if math.isfinite(margin) else math.nan
    est = SlipEstimate(state=state, stick_ratio=stick, margin=margin, friction=friction,
                       direction=direction, fit_residual=2e-6)
    return SlipFrame("scene", stamp, true, est, 0.5)


def test_a_good_estimate_passes_every_check():
    frames = [_frame(r, s, max(1 - r, 0.0) + 0.01, 0.51 if s != SLIP_STICK else math.nan, i)
              for i, (r, s) in enumerate([(0.0, SLIP_STICK), (0.5, SLIP_PARTIAL),
                                          (0.9, SLIP_PARTIAL), (1.2, SLIP_GROSS)])]
    fig = acceptance(frames)
    assert fig["pass"] == {"gross": True, "margin": True, "stick_ratio": True, "friction": True}
    assert fig["loaded"] == 4 and fig["partial"] == 2 and fig["gross"] == 1
    assert fig["mu_frames"] == 3                         # margins 0.5, 0.1 and 0
    assert fig["mu_err_max"] == pytest.approx(0.02)
    assert fig["margin_err_max"] == pytest.approx(0.01)
    report = format_slip_report([("scene", frames)])
    assert "gross slip: 1/1 gross frames reported gross" in report and "(FAIL)" not in report


def test_each_failure_is_caught():
    # a gross frame read partial, and a frame of margin 0.5 read gross
    fig = acceptance([_frame(1.2, SLIP_PARTIAL, 0.0, 0.5), _frame(0.5, SLIP_GROSS, 0.5, 0.5)])
    assert not fig["pass"]["gross"] and fig["false_gross"] == 1
    # a NaN margin where one is due counts as an infinite error
    fig = acceptance([_frame(0.5, SLIP_PARTIAL, math.nan, 0.5)])
    assert not fig["pass"]["margin"] and fig["margin_err_max"] == math.inf
    # mu NaN at margin 0.5 fails; mu 25 % off fails the max
    assert not acceptance([_frame(0.5, SLIP_STICK, 0.5, math.nan)])["pass"]["friction"]
    assert not acceptance([_frame(0.5, SLIP_PARTIAL, 0.5, 0.625)])["pass"]["friction"]
    # no output at all for a loaded frame
    frame = _frame(0.5, SLIP_PARTIAL, 0.5, 0.5)
    frame.est = None
    fig = acceptance([frame])
    assert not fig["pass"]["margin"] and not fig["pass"]["friction"]


def test_direction_error_in_degrees():
    frame = _frame(0.5, SLIP_PARTIAL, 0.5, 0.5, direction=(0.0, 1.0, 0.0))
    assert frame.direction_err_deg == pytest.approx(90.0)
    assert math.isnan(_frame(0.0, SLIP_STICK, 1.0, math.nan,
                             direction=(0.0, 0.0, 0.0)).direction_err_deg)
