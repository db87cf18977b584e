"""SensorStep: the node's way (background reference, backlog) and replay's give the same bytes."""
import signal

import numpy as np
import pytest

from tactile_sl_common import signals
from tactile_sl_common.images import to_gray
from tactile_sl_decoder.frames import bag_frames
from tactile_sl_decoder.pipeline import PatternSpec, StereoPipeline
from tactile_sl_decoder.sensor_step import SensorStep
from tactile_sl_decoder.touch.messages import touch_messages
from tactile_sl_decoder.touch.sensor import load_sensor
from tactile_sl_decoder.touch.stage import TouchParams

from ros_harness import BAGS

pytestmark = pytest.mark.slow
BAG = BAGS / "slip_two_contacts.mcap"


def _step(background: bool) -> SensorStep:
    pipeline = StereoPipeline(PatternSpec.load(None))
    return SensorStep(pipeline, load_sensor(None), TouchParams(reference_frames=1),
                      background=background, catch_up=1)


def _bytes(result, stamp):
    return [(name, repr(fields)) for name, _, fields in touch_messages(result, stamp, "pad")]


def test_live_and_offline_steps_give_every_frame_the_same_outputs():
    frames = [(f.stamp, to_gray(f.left_image), to_gray(f.right_image), f.left_info,
               f.right_info) for f in bag_frames(BAG)]
    offline, live = _step(False), _step(True)
    want, got, seen = {}, {}, []
    try:
        for stamp, left, right, li, ri in frames:
            def on_points(result, stamp=stamp):
                seen.append((stamp, len(result.points), offline.touch_ready))

            out = offline.process(left, right, li, ri, tag=stamp, on_points=on_points)
            assert out.stereo.frame_id and seen[-1][0] == stamp
            if out.touch.result is not None:
                want[stamp] = _bytes(out.touch.result, stamp)
            out = live.process(left, right, li, ri, tag=stamp)
            got.update({tag: _bytes(r, tag) for tag, r in out.touch.caught_up})
            if out.touch.result is not None:
                got[stamp] = _bytes(out.touch.result, stamp)
        stage = live.touch.stage
        if stage.preparing:
            stage._preparing.done.wait(60)
        for _ in range(len(frames) + 1):          # the node's timer, until the backlog is out
            polled = live.touch.poll()
            got.update({tag: _bytes(r, tag) for tag, r in polled.caught_up})
    finally:
        offline.close()
        live.close()
    # the first frame is the reference: its points were out before the touch stage took it
    assert seen[0][2] is False and all(ready for _, _, ready in seen[1:])
    assert len(want) == len(frames) - 1 and got == want
    assert np.all([n > 0 for _, n, _ in seen])


def test_a_signal_during_a_frame_is_raised_when_the_frame_is_done():
    """Ctrl-C amid a frame's kernels would be raised inside their Python callbacks (a
    SystemError, once a crash): under the command line's handlers it waits for the frame."""
    frame = next(iter(bag_frames(BAG)))
    step = _step(False)
    done = []

    def hook(_left, _right):                 # inside the pipeline, between its stages
        signal.raise_signal(signal.SIGINT)
        done.append("classified")

    def on_points(_result):
        done.append("points")
    try:
        with signals.as_exceptions(), pytest.raises(KeyboardInterrupt):
            step.process(to_gray(frame.left_image), to_gray(frame.right_image),
                         frame.left_info, frame.right_info, on_points=on_points,
                         label_hook=hook)
    finally:
        step.close()
    assert done == ["classified", "points"]
    assert step.touch_ready                  # the frame's touch reference was taken whole
