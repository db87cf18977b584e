"""TouchStage end to end on synthetic points: reference, pad frame, outputs, tare."""
import numpy as np
import pytest
from test_touch_traction import PITCH, SHAPE, _displacement

from tactile_sl_camera.clouds import pack_points
from tactile_sl_camera.elasticity import Elastomer
from tactile_sl_decoder.touch.messages import touch_messages
from tactile_sl_decoder.touch.reference import nominal_positions
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.stage import TouchParams, TouchStage

ROT = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
    [[1, 0, 0], [0, np.cos(0.05), -np.sin(0.05)], [0, np.sin(0.05), np.cos(0.05)]])
T = np.array([2e-4, -1e-4, 0.015])


def _points(disp, drop=()):
    rows, cols = np.divmod(np.arange(SHAPE[0] * SHAPE[1]), SHAPE[1])
    pad = nominal_positions(rows, cols, SHAPE, PITCH) + disp
    keep = np.ones(len(rows), bool)
    keep[list(drop)] = False
    return pack_points((pad @ ROT.T + T)[keep], rows[keep], cols[keep])


@pytest.fixture
def stage():
    sensor = SensorConfig(Elastomer(3e5, 0.49, 0.0))
    return TouchStage(sensor, SHAPE, PITCH, params=TouchParams(reference_frames=2))


def test_reference_then_outputs(stage):
    rng = np.random.default_rng(0)
    rest = [_displacement(stage.sensor.elastomer, [], 2e-6, rng) for _ in range(2)]
    assert stage.update(_points(rest[0])) is None and not stage.ready
    assert stage.update(_points(rest[1])) is None and stage.ready
    ref = stage.reference
    assert np.allclose(ref.pose.rotation, ROT, atol=1e-3) and ref.pose.residual_rms < 5e-6
    load = (0.05, 0.0, -0.6, 2e-3, 5e-4, -5e-4)
    disp = _displacement(stage.sensor.elastomer, [load], 2e-6, rng)
    out = stage.update(_points(disp, drop=[5, 77]))
    assert out is not None and len(out.rows) == SHAPE[0] * SHAPE[1] - 2
    assert np.sqrt(np.mean((out.displacement - np.delete(disp, [5, 77], 0)) ** 2)) < 5e-6
    assert abs(out.wrench_force[2] + 0.6) < 0.03 and abs(out.wrench_force[0] - 0.05) < 0.01
    c = out.contact
    assert c.in_contact and abs(c.normal_force - 0.6) < 0.03
    assert abs(c.centroid[0] - 5e-4) < 1e-4 and abs(c.centroid[1] + 5e-4) < 1e-4
    assert abs(c.max_depth + disp[:, 2].min()) < 0.1 * -disp[:, 2].min()
    assert abs(c.area - np.pi * 2e-3 ** 2) < 0.25 * np.pi * 2e-3 ** 2
    assert out.depth.shape == (stage.depth_grid.height, stage.depth_grid.width)
    # pressed: a tare is refused; released: accepted, and outputs stop until the new reference
    ok, text = stage.tare()
    assert not ok and "touched" in text
    out = stage.update(_points(_displacement(stage.sensor.elastomer, [], 2e-6, rng)))
    assert out is not None and not out.contact.in_contact
    ok, _ = stage.tare()
    assert ok and not stage.ready
    assert stage.update(_points(rest[0])) is None


def test_messages_carry_the_contract_fields(stage):
    rng = np.random.default_rng(1)
    for _ in range(2):
        stage.update(_points(_displacement(stage.sensor.elastomer, [], 2e-6, rng)))
    out = stage.update(_points(_displacement(stage.sensor.elastomer, [], 2e-6, rng)))
    msgs = {topic: fields for topic, _type, fields in touch_messages(out, (12, 34), "pad")}
    assert set(msgs) == {"field", "wrench", "contact", "depth", "slip"}
    names = [f["name"] for f in msgs["field"]["fields"]]
    assert names[:8] == ["x", "y", "z", "dx", "dy", "dz", "row", "col"]
    assert {"fx", "fy", "fz"} <= set(names)
    assert msgs["wrench"]["header"] == {"stamp": {"sec": 12, "nanosec": 34}, "frame_id": "pad"}
    assert msgs["contact"]["in_contact"] is False
    assert msgs["depth"]["encoding"] == "32FC1"
    slip = msgs["slip"]     # untouched: no contact, NaN where the contract says, no direction
    assert list(slip)[:7] == ["header", "state", "stick_ratio", "slip_margin",
                              "friction_coefficient", "direction", "centroid"]
    assert slip["state"] == 0 and slip["header"] == msgs["wrench"]["header"]
    assert all(np.isnan(slip[k]) for k in ("stick_ratio", "slip_margin", "friction_coefficient"))
    assert slip["direction"] == {"x": 0.0, "y": 0.0, "z": 0.0}


def test_bad_settings_are_refused():
    sensor = SensorConfig(Elastomer(3e5, 0.49, 0.0))
    with pytest.raises(ValueError, match="reference_frames"):
        TouchStage(sensor, SHAPE, PITCH, params=TouchParams(reference_frames=0))
    with pytest.raises(ValueError, match="pitch"):
        TouchStage(sensor, SHAPE, 0.0)


@pytest.mark.parametrize("thickness", [0.0, 0.002])
def test_contact_area_of_a_hertz_load(thickness):
    """The area threshold calibrated per elastomer recovers a Hertz contact's area."""
    sensor = SensorConfig(Elastomer(3e5, 0.49, thickness))
    stage = TouchStage(sensor, SHAPE, PITCH)
    rng = np.random.default_rng(4)
    stage.update(_points(_displacement(sensor.elastomer, [], 0.5e-6, rng)))
    assert stage.solver.area_fraction in (0.1, 0.15, 0.2, 0.25, 0.3, 0.35)
    radius = 2.5e-3
    disp = _displacement(sensor.elastomer, [(0.0, 0.0, -1.0, radius, 2.5e-4, 0.0)], 0.5e-6, rng)
    out = stage.update(_points(disp))
    assert abs(out.contact.area / (np.pi * radius ** 2) - 1) < 0.15
    assert len(out.contact.region_force) == 1


def test_background_reference_gives_the_same_outputs_without_blocking_frames():
    sensor = SensorConfig(Elastomer(3e5, 0.49, 0.0))
    inline = TouchStage(sensor, SHAPE, PITCH, params=TouchParams(reference_frames=1))
    live = TouchStage(sensor, SHAPE, PITCH, params=TouchParams(reference_frames=1),
                      background=True)
    rng = np.random.default_rng(3)
    rest = _points(_displacement(sensor.elastomer, [], 2e-6, rng))
    assert inline.update(rest) is None and inline.ready
    assert live.update(rest) is None and not live.ready and live.preparing
    pressed = _points(_displacement(sensor.elastomer, [(0.0, 0.0, -0.4, 2e-3, 0.0, 0.0)],
                                     2e-6, rng))
    live._preparing.done.wait(60)      # what the node's timer waits for
    want = inline.update(pressed)
    got = live.update(pressed)         # installs the prepared reference, then this frame
    assert got is not None and live.ready and not live.preparing
    assert np.array_equal(got.force, want.force) and np.array_equal(got.depth, want.depth,
                                                                    equal_nan=True)
    for name in ("displacement", "wrench_force", "wrench_moment"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert got.contact == want.contact


def test_a_tare_drops_a_reference_still_being_prepared():
    sensor = SensorConfig(Elastomer(3e5, 0.49, 0.0))
    live = TouchStage(sensor, SHAPE, PITCH, params=TouchParams(reference_frames=1),
                      background=True)
    rng = np.random.default_rng(4)
    assert live.update(_points(_displacement(sensor.elastomer, [], 2e-6, rng))) is None
    old = live._preparing
    ok, _ = live.tare()
    assert ok and not live.preparing and not live.ready
    old.done.wait(60)
    assert not live.poll() and not live.ready     # the dropped one is never installed
