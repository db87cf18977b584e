"""The slip estimate on simulated fields with known truth (no rendering), and its edge cases.

The simulator's friction loads (Cattaneo-Mindlin traction, sim/friction.py) give the
displacement at every cell through the elasticity module; small noise is added (1 um in x,
y and 3 um in z, about what the decoder measures) and the points go through the whole
TouchStage (reference, traction map, contact state, slip).
"""
import math

import numpy as np
import pytest

from tactile_sl_common.clouds import pack_points
from tactile_sl_common.elasticity import Elastomer
from tactile_sl_decoder.contract import SLIP_GROSS, SLIP_NO_CONTACT, SLIP_PARTIAL, SLIP_STICK
from tactile_sl_decoder.touch.messages import slip_fields, slip_markers
from tactile_sl_decoder.touch.reference import nominal_positions
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.slip import SlipEstimate, SlipEstimator, SlipParams
from tactile_sl_decoder.touch.stage import TouchStage
from tactile_sl_sim.contact import FieldGrid, PadParams
from tactile_sl_sim.loads import LoadContact, strongest_slip

SHAPE, PITCH = (28, 30), 5e-4
HALF = Elastomer(3.0e5, 0.49, 0.0)
LAYER = Elastomer(3.0e5, 0.49, 0.002)
GRID = {"x0": -0.0105, "y0": -0.0105, "spacing": 5e-5, "nx": 421, "ny": 421}
ROWS, COLS = np.divmod(np.arange(SHAPE[0] * SHAPE[1]), SHAPE[1])
NOMINAL = nominal_positions(ROWS, COLS, SHAPE, PITCH)
NOISE = np.array([1e-6, 1e-6, 3e-6])


def _points(disp: np.ndarray) -> np.ndarray:
    """Contract points of the pad displaced by ``disp`` (the pad frame 15 mm in front)."""
    xyz = NOMINAL + disp + np.array([0.0, 0.0, 0.015])
    return pack_points(xyz, ROWS, COLS)


def _field(loads: list[LoadContact], rng: np.random.Generator) -> np.ndarray:
    g = FieldGrid.build(loads, PadParams(), **GRID)
    return g.sample(NOMINAL[:, 0], NOMINAL[:, 1]) + rng.normal(0.0, NOISE, (len(ROWS), 3))


def _load(ratio: float, mu: float = 0.5, normal: float = 0.5, radius: float = 0.003,
          angle: float = 0.5, x: float = 4e-4, y: float = -3e-4,
          elastomer: Elastomer = HALF) -> LoadContact:
    q = ratio * mu * normal
    return LoadContact(radius=radius, x=x, y=y, elastomer=elastomer, friction=mu,
                       force=(q * math.cos(angle), q * math.sin(angle), -normal))


@pytest.fixture(scope="module")
def stages():
    """A touch stage per elastomer with its reference taken (untouched, noisy)."""
    rng = np.random.default_rng(5)
    out = {}
    for elastomer in (HALF, LAYER):
        stage = TouchStage(SensorConfig(elastomer), SHAPE, PITCH)
        assert stage.update(_points(rng.normal(0.0, NOISE, (len(ROWS), 3)))) is None
        out[elastomer] = stage
    return out


def _estimate(stages, loads: list[LoadContact], seed: int = 0) -> SlipEstimate:
    stage = stages[loads[0].elastomer]
    out = stage.update(_points(_field(loads, np.random.default_rng(seed))))
    assert out is not None
    return out.slip


@pytest.mark.parametrize("ratio", [0.5, 0.65, 0.9, 1.0, 1.3])
def test_a_ramp_on_a_half_space(stages, ratio):
    load = _load(ratio)
    true = load.slip
    est = _estimate(stages, [load], seed=int(ratio * 10))
    assert abs(est.margin - true.margin) < 0.04
    assert abs(est.stick_ratio - true.stick_ratio) < 0.04
    assert est.state == (SLIP_GROSS if true.margin <= 0.05 else SLIP_PARTIAL)
    assert est.friction == pytest.approx(0.5, rel=0.05)
    assert est.direction == pytest.approx(true.direction, abs=0.02)
    assert est.contact_radius == pytest.approx(0.003, rel=0.03)
    assert est.normal_force == pytest.approx(0.5, rel=0.03)
    assert est.tangential_force == pytest.approx(math.hypot(*true.transmitted), rel=0.05)
    assert est.centroid[:2] == pytest.approx((4e-4, -3e-4), abs=3e-5)
    assert est.fit_residual < 3e-6


def test_a_thin_annulus_reads_stick_and_keeps_mu_unknown(stages):
    est = _estimate(stages, [_load(0.1)], seed=3)         # true margin 0.9
    assert est.state == SLIP_STICK and math.isnan(est.friction)
    assert abs(est.margin - 0.9) < 0.1 and est.direction[0] > 0.8


def test_a_layer_bonded_to_the_window(stages):
    load = _load(0.6, mu=0.7, normal=1.0, elastomer=LAYER)
    est = _estimate(stages, [load], seed=11)
    assert abs(est.margin - load.slip.margin) < 0.06
    assert est.friction == pytest.approx(0.7, rel=0.08)


def test_no_tangential_load(stages):
    est = _estimate(stages, [_load(0.0)], seed=12)
    assert est.state == SLIP_STICK and est.margin == 1.0 and est.stick_ratio == 1.0
    assert math.isnan(est.friction) and est.direction == (0.0, 0.0, 0.0)
    assert est.tangential_force == 0.0 and est.contact_radius == pytest.approx(0.003, rel=0.1)


def test_no_contact(stages):
    stage = stages[HALF]
    rng = np.random.default_rng(13)
    out = stage.update(_points(rng.normal(0.0, NOISE, (len(ROWS), 3))))
    s = out.slip
    assert s.state == SLIP_NO_CONTACT and s.direction == (0.0, 0.0, 0.0)
    assert math.isnan(s.stick_ratio) and math.isnan(s.margin) and math.isnan(s.friction)
    fields = slip_fields(s, (3, 4), "pad")
    assert fields["state"] == 0 and math.isnan(fields["slip_margin"])
    assert [m["action"] for m in slip_markers(s)] == [3]          # DELETEALL


def test_two_contacts_measure_the_one_pressing_hardest(stages):
    strong = _load(0.5, normal=0.8, x=-0.003, y=-0.0015, angle=0.0)
    weak = LoadContact(radius=0.002, x=0.0035, y=0.002, force=(0.0, 0.045, -0.3),
                       friction=0.5)
    assert strongest_slip([strong, weak]) == strong.slip
    est = _estimate(stages, [strong, weak], seed=14)
    assert est.centroid[:2] == pytest.approx((-0.003, -0.0015), abs=1.5e-4)
    assert abs(est.margin - 0.5) < 0.05 and est.friction == pytest.approx(0.5, rel=0.05)
    # the other one pressing harder: it is measured (partial slip, margin 0.7)
    weak2 = LoadContact(radius=0.002, x=0.0035, y=0.002, force=(0.0, 0.15, -1.0),
                        friction=0.5)
    est = _estimate(stages, [strong, weak2], seed=15)
    assert est.centroid[:2] == pytest.approx((0.0035, 0.002), abs=1e-4)
    assert abs(est.margin - weak2.slip.margin) < 0.15


@pytest.mark.parametrize("x", [0.0065, 0.0072])
def test_a_contact_leaving_the_pad_gives_defined_outputs(stages, x):
    """Partly off the pad (7.25 mm half-width), then centred on its edge: no exception,
    and every figure a number in range or NaN."""
    est = _estimate(stages, [_load(0.6, x=x, y=0.0)], seed=16)
    assert est.state in (SLIP_NO_CONTACT, SLIP_STICK, SLIP_PARTIAL, SLIP_GROSS)
    for value in (est.stick_ratio, est.margin):
        assert math.isnan(value) or 0.0 <= value <= 1.0
    assert math.isnan(est.friction) or est.friction > 0
    fields = slip_fields(est, (1, 2), "pad")
    assert set(fields) >= {"state", "stick_ratio", "slip_margin", "friction_coefficient"}


def test_too_few_cells_is_stick_with_unknown_margin():
    estimator = SlipEstimator(HALF, PITCH)
    rest = NOMINAL[:6, :2]
    est = estimator.estimate(rest, np.zeros((6, 3)), np.full(6, 0.05), True, 0.25)
    assert est.state == SLIP_STICK and math.isnan(est.margin) and math.isnan(est.friction)
    assert 0 < est.cells < SlipParams().min_cells
    # nothing presses although the contact state says so (hysteresis): no contact
    est = estimator.estimate(rest, np.zeros((6, 3)), np.zeros(6), True, 0.25)
    assert est.state == SLIP_NO_CONTACT
    # NaN displacements are left out, never propagated
    disp = np.full((6, 3), np.nan)
    est = estimator.estimate(rest, disp, np.full(6, 0.05), True, 0.25)
    assert est.state == SLIP_STICK and est.cells == 0


def test_markers_follow_the_state():
    gross = SlipEstimate(state=SLIP_GROSS, stick_ratio=0.0, margin=0.0, friction=0.5,
                         direction=(0.0, 1.0, 0.0), contact_radius=0.003, stick_radius=0.0)
    markers = slip_markers(gross)
    assert [m["id"] for m in markers] == [0, 2]          # disc and arrow, no stick disc
    assert markers[0]["color"][0] > 0.8 > markers[0]["color"][1]
    assert markers[1]["orientation"]["z"] == pytest.approx(math.sin(math.pi / 4))
    partial = SlipEstimate(state=SLIP_PARTIAL, stick_ratio=0.5, margin=0.35, friction=0.5,
                           direction=(1.0, 0.0, 0.0), contact_radius=0.003,
                           stick_radius=0.0021)
    markers = slip_markers(partial)
    assert [m["id"] for m in markers] == [0, 1, 2]
    assert markers[1]["scale"]["x"] == pytest.approx(0.0042)


@pytest.mark.parametrize("kwargs, message", [
    ({"radius_range": (1.2, 1.5)}, "radius_range"), ({"window": 0.9}, "window"),
    ({"radius_step": 2.0}, "radius_step"), ({"slip_seen": 1.0}, "slip_seen"),
    ({"noise_normal": 0.0}, "noise"), ({"min_cells": 2}, "min_cells"),
    ({"max_cells": 10}, "max_cells"), ({"radii_per_contact": 2}, "radii_per_contact")])
def test_bad_settings_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SlipParams(**kwargs).validate()


def test_slip_only_when_wanted_and_the_same_when_it_is(stages) -> None:
    """A node asks for slip only while something subscribes; the estimate has no history,
    so a frame estimated after frames that were not is the same as one always estimated."""
    stage = stages[HALF]
    loads = [_load(0.6)]
    always = _estimate(stages, loads, seed=3)
    stage.slip_wanted = lambda: False
    try:
        out = stage.update(_points(_field(loads, np.random.default_rng(4))))
        assert out is not None and out.slip is None
        assert out.wrench_force[2] < 0           # the rest of the frame is there
    finally:
        stage.slip_wanted = lambda: True
    again = _estimate(stages, loads, seed=3)
    assert again == always and again.state != SLIP_NO_CONTACT
