"""TouchStage end to end on synthetic points: reference, pad frame, outputs, tare."""
import numpy as np
import pytest
from test_touch_traction import PITCH, SHAPE, _displacement

from tactile_sl_common.clouds import pack_points
from tactile_sl_common.elasticity import Elastomer
from tactile_sl_decoder.touch.contact import depth_map
from tactile_sl_decoder.touch.messages import touch_messages
from tactile_sl_decoder.touch.reference import nominal_positions
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.stage import TouchParams, TouchStage

ROT = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
    [[1, 0, 0], [0, np.cos(0.05), -np.sin(0.05)], [0, np.sin(0.05), np.cos(0.05)]])
T = np.array([2e-4, -1e-4, 0.015])


# A live stage computes its inversion (no disk cache): a reference read back from the cache
# would be ready before the queue of frames waiting for it could be exercised.
LIVE = TouchParams(reference_frames=1, solver_cache=False)

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
    # the depth map is made on first use (a node publishes it only while heard), from the
    # frame's cell grid of indentation
    assert "depth" not in vars(out)
    assert out.depth.shape == (stage.depth_grid.height, stage.depth_grid.width)
    assert "depth" in vars(out) and out.depth is out.depth
    assert np.array_equal(out.depth, depth_map(out.indent, stage.params.contact.depth_upsample),
                          equal_nan=True)
    assert np.nanmax(out.depth) == pytest.approx(np.nanmax(out.indent))
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
    # issue 28, item 3: a layer the kernel cannot resolve is refused at load (it used to fail
    # with a LinAlgError when the first reference was prepared)
    thin = SensorConfig(Elastomer(3e5, 0.49, 1e-5), source="thin.yaml")
    with pytest.raises(ValueError, match="thin.yaml: .*quarter of the cell pitch"):
        TouchStage(thin, SHAPE, PITCH)


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
    live = TouchStage(sensor, SHAPE, PITCH, params=LIVE, background=True)
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
    live = TouchStage(sensor, SHAPE, PITCH, params=LIVE, background=True)
    rng = np.random.default_rng(4)
    assert live.update(_points(_displacement(sensor.elastomer, [], 2e-6, rng))) is None
    old = live._preparing
    ok, _ = live.tare()
    assert ok and not live.preparing and not live.ready
    old.done.wait(60)
    assert not live.poll() and not live.ready     # the dropped one is never installed


def _same(got, want):
    assert np.array_equal(got.force, want.force)
    assert np.array_equal(got.depth, want.depth, equal_nan=True)
    for name in ("displacement", "wrench_force", "wrench_moment"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert got.contact == want.contact


def test_frames_during_a_background_preparation_get_their_outputs_in_order():
    """Frames that come while the reference is prepared are queued, then given outputs."""
    sensor = SensorConfig(Elastomer(3e5, 0.49, 0.0))
    inline = TouchStage(sensor, SHAPE, PITCH, params=TouchParams(reference_frames=1))
    live = TouchStage(sensor, SHAPE, PITCH, params=LIVE, background=True)
    rng = np.random.default_rng(5)
    rest = _points(_displacement(sensor.elastomer, [], 2e-6, rng))
    inline.update(rest)
    live.update(rest)
    gate = live._preparing
    frames = [_points(_displacement(sensor.elastomer, [(0.0, 0.0, -f, 2e-3, 0.0, 0.0)],
                                    2e-6, rng)) for f in (0.1, 0.4, 0.8)]
    if gate.done.is_set():           # a very fast machine: the queue is not exercised
        pytest.skip("the preparation finished before the next frame")
    for i, pts in enumerate(frames[:2]):
        assert live.update(pts, tag=i) is None
    assert live.pending == 2 and live.drain() == []
    gate.done.wait(60)
    want = [inline.update(p) for p in frames]
    got = live.update(frames[2], tag=2)     # installs the reference, catches up, then this
    assert live.caught_up == 2
    caught = live.drain(1) + live.drain(5)  # in order, a few at a time
    assert [tag for tag, _ in caught] == [0, 1] and live.pending == 0
    for (_, r), w in zip(caught, want[:2]):
        _same(r, w)
    _same(got, want[2])
    assert live.pending_dropped == 0 and live.drain() == []


def test_the_pending_queue_is_bounded_and_cleared_by_a_tare():
    sensor = SensorConfig(Elastomer(3e5, 0.49, 0.0))
    live = TouchStage(sensor, SHAPE, PITCH,
                      params=TouchParams(reference_frames=1, max_pending_frames=2,
                                         solver_cache=False),
                      background=True)
    rng = np.random.default_rng(6)
    live.update(_points(_displacement(sensor.elastomer, [], 2e-6, rng)))
    gate = live._preparing
    pts = _points(_displacement(sensor.elastomer, [], 2e-6, rng))
    for i in range(4):
        live._queue(i, pts)             # as update() does while the preparation runs
    assert live.pending == 2 and live.pending_dropped == 2
    assert [tag for tag, _ in live._pending] == [2, 3]   # the newest are kept
    ok, _ = live.tare()
    assert ok and live.pending == 0
    gate.done.wait(60)
    assert not live.poll() and live.drain() == []
    with pytest.raises(ValueError, match="max_pending_frames"):
        TouchParams(max_pending_frames=-1).validate()


def test_a_tare_with_the_same_cells_reuses_the_inversion():
    """A new reference of the same cells is ready at once, with the same outputs."""
    sensor = SensorConfig(Elastomer(3e5, 0.49, 0.0))
    live = TouchStage(sensor, SHAPE, PITCH, params=LIVE, background=True)
    rng = np.random.default_rng(7)
    live.update(_points(_displacement(sensor.elastomer, [], 2e-6, rng)))
    live._preparing.done.wait(60)
    live.poll()
    solver = live.solver
    assert live.tare()[0]
    rest = _points(_displacement(sensor.elastomer, [], 2e-6, rng))
    assert live.update(rest) is None
    assert live.ready and not live.preparing and live.solver is solver   # no queue at all
    fresh = TouchStage(sensor, SHAPE, PITCH, params=TouchParams(reference_frames=1))
    fresh.update(rest)
    pressed = _points(_displacement(sensor.elastomer, [(0.0, 0.0, -0.5, 2e-3, 0.0, 0.0)],
                                    2e-6, rng))
    _same(live.update(pressed), fresh.update(pressed))
    # other cells: a new inversion, prepared in the background again
    live.update(rest)                   # released first: a tare is refused while pressed
    assert live.tare()[0]
    assert live.update(_points(_displacement(sensor.elastomer, [], 2e-6, rng), drop=[3])) is None
    assert live.preparing


def test_contact_thresholds_changed_live_apply_to_the_next_frame():
    """Issue 28, item 2: contact_force_on/off set live were accepted and ignored (the stage
    kept a copy of the thresholds taken with the reference)."""
    sensor = SensorConfig(Elastomer(3e5, 0.49, 0.0))
    stage = TouchStage(sensor, SHAPE, PITCH)
    rng = np.random.default_rng(5)
    stage.update(_points(_displacement(sensor.elastomer, [], 0.5e-6, rng)))

    def frame(newtons):
        disp = _displacement(sensor.elastomer, [(0.0, 0.0, -newtons, 2e-3, 0.0, 0.0)], 0.5e-6,
                             rng)
        return stage.update(_points(disp)).contact

    assert frame(0.05).in_contact and frame(0.5).in_contact        # defaults: 10 / 5 mN
    stage.params.contact.force_on, stage.params.contact.force_off = 1.0, 0.8
    assert not frame(0.05).in_contact and not frame(0.5).in_contact
    assert frame(1.2).in_contact and frame(0.9).in_contact          # on above 1 N, held ...
    assert not frame(0.5).in_contact                                # ... off below 0.8 N
    assert stage.contact_params.area_fraction == stage.solver.area_fraction


def test_forces_and_contact_state_made_on_first_use_are_those_of_their_frame():
    """The per-cell forces, the contact state and the depth map are made only when asked
    for (a node publishes them only while heard); made late, after more frames and a live
    change, they are the frame's own, and the in_contact hysteresis runs every frame
    regardless."""
    sensor = SensorConfig(Elastomer(3e5, 0.49, 0.0))
    eager, lazy = (TouchStage(sensor, SHAPE, PITCH) for _ in range(2))
    lazy.slip_wanted = lambda: False        # a node nobody asks for slip (slip needs forces)
    rng = np.random.default_rng(11)
    loads = [0.0, 0.3, 0.008, 0.006, 0.004, 0.012, 0.5]   # on, held (8 and 6 mN), off, ...
    frames = [_points(_displacement(sensor.elastomer, [(0.02, 0.0, -f, 1.5e-3, -5e-4, 0.0)]
                                    if f else [], 1e-6, rng)) for f in loads]
    for stage in (eager, lazy):
        assert stage.update(frames[0]) is None
    want = [eager.update(p) for p in frames[1:]]
    got = [lazy.update(p) for p in frames[1:]]
    assert [w.contact.in_contact for w in want] == [True, True, True, False, True, True]
    assert all(not {"force", "contact", "depth"} & set(vars(g)) for g in got)
    assert [g.in_contact for g in got] == [w.contact.in_contact for w in want]
    assert [g.wrench_force.tolist() for g in got] == [w.wrench_force.tolist() for w in want]
    lazy.params.contact.force_on = lazy.params.contact.force_off = 10.0   # after the frames
    lazy.params.contact.core_fraction = 0.9
    before = dict(got[-1].timings_ms)
    for i, (g, w) in enumerate(zip(got[::-1], want[::-1])):      # made last to first
        if i % 2:
            assert np.array_equal(g.force, w.force)                 # forces first, or ...
        assert g.contact == w.contact                               # ... with the contact
        assert np.array_equal(g.force, w.force)
        assert np.array_equal(g.depth, w.depth, equal_nan=True)
    assert got[-1].contact.area > 0 and np.abs(got[-1].force[:, 2]).sum() > 0
    # the time they took is added to the frame's traction, contact and touch times
    added = {part: got[-1].timings_ms[part] - before[part] for part in before}
    assert added["traction"] > 0 and added["contact"] > 0
    assert added["touch"] == pytest.approx(added["traction"] + added["contact"])
    # the force calibration's input is the last frame's, made when asked for
    disp, valid, forces = lazy.last_solve
    assert np.array_equal(forces, eager.last_solve[2]) and valid.all()
    # the tare asks the last frame's contact state: refused while pressed
    ok, text = lazy.tare()
    assert not ok and "touched" in text
