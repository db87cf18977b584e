"""Live checks of the decoder's touch outputs: a phased bag, hysteresis and tare expectations.

Shared by ``tools/soak_touch.py`` (minutes of ``tare`` calls and live parameter changes on a
looping replay) and the process tests (issue 28).  No rclpy: the callers convert messages.

* :func:`write_phase_bag` builds a bag that alternates an untouched phase with a pressed
  one from frames of a touch bag, so that a ``tare`` called early in an untouched phase is
  accepted and one called in a pressed phase is refused for real (the pad is pressed in by
  hundreds of micrometres, far above ``tare_max_depth``).
* :class:`ContactCheck` checks every ``contact`` message's ``in_contact`` against the
  ``contact_force_on`` / ``contact_force_off`` hysteresis in force when its frame was
  processed (a change is in force for frames stamped after the answer to the change; a
  frame received before the request saw the old values; in between either is accepted).
* :func:`tare_expected` says whether the stage accepts a tare after a given frame.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from tactile_sl_common.bag_io import BagError, BagReader, BagWriter, restamp_cdr

IMAGE_TOPICS_SUFFIXES = ("/image_raw", "/camera_info")


def write_phase_bag(source: str | Path, out: str | Path, untouched: Sequence[int],
                    pressed: Sequence[int], untouched_frames: int, pressed_frames: int,
                    period_s: float = 0.1) -> int:
    """A bag of ``untouched_frames`` frames then ``pressed_frames`` frames, one phase each.

    Frames are stereo frames of ``source`` counted from 0 in stamp order (images and
    camera_info only); the untouched phase cycles through the indices ``untouched``, the
    pressed one through ``pressed``.  Every frame gets a new stamp, ``period_s`` apart from
    the first frame's stamp (log time = stamp).  Returns the number of frames written.
    """
    reader = BagReader(source)
    frames: dict[int, list] = {}
    for raw in reader.raw_messages():
        if raw.topic.endswith(IMAGE_TOPICS_SUFFIXES):
            frames.setdefault(raw.log_time_ns, []).append(raw)
    stamps = sorted(frames)
    wanted = list(untouched) + list(pressed)
    if not stamps or max(wanted) >= len(stamps) or min(wanted) < 0:
        raise BagError(f"{source}: has {len(stamps)} stereo frames, frames {wanted} wanted")
    order = ([untouched[i % len(untouched)] for i in range(untouched_frames)]
             + [pressed[i % len(pressed)] for i in range(pressed_frames)])
    start = stamps[0]
    step = int(round(period_s * 1e9))
    with BagWriter(out) as bag:
        for k, index in enumerate(order):
            t = start + k * step
            for raw in frames[stamps[index]]:
                bag.write_raw(raw.topic, raw.schema_name,
                              restamp_cdr(raw.data, t // 10**9, t % 10**9), t)
    return len(order)


def tare_expected(in_contact: bool, max_depth: float, tare_max_depth: float) -> bool:
    """Whether a tare after a frame with this contact state is accepted (the stage's rule)."""
    return not (in_contact or max_depth > tare_max_depth)


@dataclass(frozen=True)
class Thresholds:
    """contact_force_on / contact_force_off (N)."""

    on: float
    off: float

    def in_contact(self, normal_force: float, was_in_contact: bool) -> bool:
        """The stage's hysteresis: on above ``on``, held until the force drops to ``off``."""
        return normal_force > (self.off if was_in_contact else self.on)


@dataclass
class _Change:
    requested_ns: int
    answered_ns: int
    thresholds: Thresholds


@dataclass
class ContactCheck:
    """``in_contact`` of every contact message against the thresholds in force.

    Call :meth:`change` after each live change (with the wall-clock times of the request
    and of its answer, the clock of the frames' stamps: a restamping replay on the same
    machine), :meth:`reset` after an accepted tare (the stage starts out of contact, but a
    message in flight may still be from before), and :meth:`check` for every contact
    message in arrival order (the node publishes them reliably, in processing order).
    """

    initial: Thresholds
    changes: list[_Change] = field(default_factory=list)
    checked: int = 0
    held: int = 0            # frames where the hysteresis held the state between off and on
    either: int = 0          # frames of a change in flight: either threshold pair accepted
    violations: list[str] = field(default_factory=list)
    _was: bool | None = None

    def change(self, thresholds: Thresholds, requested_ns: int, answered_ns: int) -> None:
        """New thresholds, asked for at ``requested_ns`` and confirmed at ``answered_ns``."""
        self.changes.append(_Change(int(requested_ns), int(answered_ns), thresholds))

    def reset(self) -> None:
        """A tare was accepted: the state of the next message's predecessor is unknown."""
        self._was = None

    def in_force(self, stamp_ns: int, arrived_ns: int) -> list[Thresholds]:
        """Thresholds that may have applied to a frame (its stamp, its message's arrival)."""
        pairs = [self.initial] + [c.thresholds for c in self.changes]
        first = sum(1 for c in self.changes if c.answered_ns < stamp_ns)
        last = sum(1 for c in self.changes if c.requested_ns < arrived_ns)
        return pairs[min(first, last):max(first, last) + 1]

    def check(self, stamp_ns: int, arrived_ns: int, in_contact: bool,
              normal_force: float) -> bool:
        """True if ``in_contact`` follows from the force and the thresholds in force."""
        candidates = self.in_force(stamp_ns, arrived_ns)
        if self._was is None:
            allowed = {t.in_contact(normal_force, w) for t in candidates for w in (False, True)}
        else:
            allowed = {t.in_contact(normal_force, self._was) for t in candidates}
        self.checked += 1
        self.either += len(candidates) > 1
        ok = in_contact in allowed
        if ok and self._was and in_contact and all(normal_force <= t.on for t in candidates):
            self.held += 1
        if not ok:
            self.violations.append(
                f"frame {stamp_ns}: in_contact {in_contact} with normal force "
                f"{normal_force * 1e3:.1f} mN, previous {self._was}, thresholds "
                + " or ".join(f"on {t.on * 1e3:g} / off {t.off * 1e3:g} mN" for t in candidates))
        self._was = in_contact
        return ok
