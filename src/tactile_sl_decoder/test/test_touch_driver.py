"""TouchDriver: the tare policy, the frame that completed the reference, the backlog."""
import numpy as np
import pytest
from test_touch_stage import _points, _same
from test_touch_traction import PITCH, SHAPE, _displacement

from tactile_sl_common.elasticity import Elastomer
from tactile_sl_decoder.touch.driver import TouchDriver
from tactile_sl_decoder.touch.reference import ReferenceError
from tactile_sl_decoder.touch.sensor import SensorConfig
from tactile_sl_decoder.touch.stage import TouchParams

SENSOR = SensorConfig(Elastomer(3e5, 0.49, 0.0))


def _one_row(points):
    """The frame's cells of pattern row 0 only: a reference that cannot fix the pad frame."""
    return points[points["row"] == 0]


def test_an_unusable_reference_is_dropped_and_taken_again_from_the_next_frames():
    driver = TouchDriver(SENSOR, SHAPE, PITCH, params=TouchParams(reference_frames=1))
    rng = np.random.default_rng(1)
    rest = _points(_displacement(SENSOR.elastomer, [], 2e-6, rng))
    failed = driver.frame(_one_row(rest), tag="a", frame_id="cam")
    assert isinstance(failed.reference_failed, ReferenceError)
    assert failed.result is None and failed.reference_ready is None and not driver.ready
    taken = driver.frame(rest, tag="b", frame_id="cam")
    assert taken.reference_failed is None and driver.ready
    assert taken.reference_ready is not None
    assert (taken.reference_ready.tag, taken.reference_ready.frame_id) == ("b", "cam")
    assert taken.reference_ready.reference is driver.stage.reference
    pressed = _points(_displacement(SENSOR.elastomer, [(0.0, 0.0, -0.4, 2e-3, 0.0, 0.0)],
                                     2e-6, rng))
    out = driver.frame(pressed, tag="c")
    assert out.result is not None and out.reference_ready is None and out.caught_up == []


def test_the_backlog_of_a_background_reference_comes_back_in_order_a_few_per_call():
    inline = TouchDriver(SENSOR, SHAPE, PITCH, params=TouchParams(reference_frames=1))
    live = TouchDriver(SENSOR, SHAPE, PITCH,    # computed, not read back: the queue is used
                       params=TouchParams(reference_frames=1, solver_cache=False),
                       background=True, catch_up=2)
    rng = np.random.default_rng(2)
    rest = _points(_displacement(SENSOR.elastomer, [], 2e-6, rng))
    frames = [_points(_displacement(SENSOR.elastomer, [(0.0, 0.0, -f, 2e-3, 0.0, 0.0)],
                                    2e-6, rng)) for f in (0.1, 0.2, 0.4, 0.8)]
    assert inline.frame(rest).reference_ready is not None
    want = [inline.frame(p).result for p in frames]
    first = live.frame(rest, tag=0, frame_id="left_optical")
    assert first.reference_ready is None and live.stage.preparing
    gate = live.stage._preparing
    if gate.done.is_set():           # a very fast machine: the queue is not exercised
        pytest.skip("the preparation finished before the next frame")
    for i, pts in enumerate(frames[:3], 1):
        waiting = live.frame(pts, tag=i)
        assert waiting.result is None and waiting.caught_up == []
    gate.done.wait(60)
    polled = live.poll()              # what the node's timer does
    assert polled.reference_ready is not None
    assert (polled.reference_ready.tag, polled.reference_ready.frame_id) == (0, "left_optical")
    last = live.frame(frames[3], tag=4)
    assert [tag for tag, _ in polled.caught_up + last.caught_up] == [1, 2, 3]
    assert len(polled.caught_up) == 2       # at most catch_up per call
    for (_, got), expected in zip(polled.caught_up + last.caught_up, want[:3]):
        _same(got, expected)
    _same(last.result, want[3])
    assert live.poll().caught_up == [] and not live.stage.caught_up


def test_a_restart_keeps_the_sensor_and_the_live_settings():
    params = TouchParams(reference_frames=1)
    driver = TouchDriver(SENSOR, SHAPE, PITCH, params=params)
    driver.frame(_points(_displacement(SENSOR.elastomer, [], 2e-6, np.random.default_rng(3))))
    assert driver.ready
    params.contact.force_on = 0.05             # a live change, written into the params

    def nobody_listens() -> bool:
        return False

    driver.stage.slip_wanted = nobody_listens  # what a node sets
    driver.restart(mirrored=True)
    assert not driver.ready and driver.stage.mirrored
    assert driver.stage.params is params and driver.stage.sensor is SENSOR
    assert driver.stage.slip_wanted is nobody_listens
