"""Frames put together by stamp; the newest complete one shown; rates, latency, drops."""
import viewer_messages as msgs

from tactile_sl_viewer.assembly import FrameAssembler

S = 1_000_000_000


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def make(keep=8, grace=0.1):
    clock = Clock()
    wall = {"ns": 0}
    assembler = FrameAssembler(keep=keep, grace_s=grace, clock=clock, wall_ns=lambda: wall["ns"])
    return assembler, clock, wall


def test_the_newest_frame_with_all_its_parts_is_shown():
    a, clock, _ = make()
    for stamp in (1 * S, 2 * S):
        a.add("image", msgs.image(stamp), stamp)
        a.add("points", msgs.points(stamp), stamp)
        a.add("wrench", msgs.wrench(stamp), stamp)
    frame = a.latest()
    assert frame.stamp_ns == 2 * S and set(frame.parts) == {"image", "points", "wrench"}
    # frame 3: image and points, its wrench not yet in: frame 2 stays on screen ...
    a.add("image", msgs.image(3 * S), 3 * S)
    a.add("points", msgs.points(3 * S), 3 * S)
    assert a.latest().stamp_ns == 2 * S
    # ... until the wrench comes, or the grace time is over
    clock.t += 0.2
    assert a.latest().stamp_ns == 3 * S
    a.add("wrench", msgs.wrench(3 * S), 3 * S)
    assert a.latest().key == (3 * S, ("image", "points", "wrench"))


def test_every_part_of_a_shown_frame_has_its_stamp():
    a, clock, _ = make()
    a.add("wrench", msgs.wrench(1 * S), 1 * S)
    a.add("image", msgs.image(2 * S), 2 * S)          # the next frame's image, no output yet
    assert a.latest() is None                          # frame 1 may still get its image
    clock.t += 0.2
    frame = a.latest()
    assert frame.stamp_ns == 1 * S and "image" not in frame.parts


def test_images_alone_are_shown_while_no_decoder_runs():
    a, clock, _ = make()
    assert a.latest() is None
    a.add("image", msgs.image(1 * S), 1 * S)
    a.add("image", msgs.image(2 * S), 2 * S)
    assert a.latest().stamp_ns == 2 * S


def test_only_the_last_frames_are_kept_and_a_bag_starting_over_resets():
    a, clock, _ = make(keep=3)
    for k in range(1, 10):
        a.add("points", msgs.points(k * S), k * S)
    assert len(a._frames) == 3
    a.add("points", msgs.points(2 * S), 2 * S)        # far older: time went back (a bag loop)
    assert a.latest().stamp_ns == 2 * S and len(a._frames) == 1


def test_rates_latency_and_frames_the_decoder_dropped():
    a, clock, wall = make()
    for k in range(11):                                # 10 Hz camera, decoder every other frame
        stamp = 1000 * S + k * S // 10
        clock.t += 0.1
        wall["ns"] = stamp + 30_000_000                # 30 ms after the stamp
        a.add("image", msgs.image(stamp), stamp)
        if k % 2 == 0:
            a.add("points", msgs.points(stamp), stamp)
    clock.t += 1.5
    stats = a.stats()
    assert abs(stats["camera_hz"] - 10.0) < 1e-6
    assert abs(stats["decoded_hz"] - 5.0) < 1e-6
    assert abs(stats["latency_ms"] - 30.0) < 1e-6
    assert stats["dropped_total"] == 5 and stats["dropped_10s"] == 5


def test_stamps_far_from_the_clock_have_no_latency_and_a_silent_decoder_drops_nothing():
    a, clock, wall = make()
    wall["ns"] = 10**18
    for k in range(5):
        clock.t += 0.1
        a.add("image", msgs.image(k * S), k * S)
    a.add("points", msgs.points(4 * S), 4 * S)
    clock.t += 5.0
    stats = a.stats()
    assert stats["latency_ms"] is None                 # a bag's stamps, not live
    assert stats["dropped_total"] == 0                 # the decoder was not running then


def test_listeners_hear_every_message():
    a, _, _ = make()
    heard = []
    a.on_change(lambda: heard.append(a.version))
    a.add("image", msgs.image(S), S)
    a.add("points", msgs.points(S), S)
    assert heard == [1, 2]
