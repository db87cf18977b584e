"""Tare and live touch settings on a running decoder (issue 28, items 1 and 2).

A replay loops a bag that alternates one second of the untouched pad with one second of a
pressed one (0.5 N and 2 N frames of ``touch_halfspace``), so a ``tare`` early in the
untouched phase is accepted and one in the pressed phase is refused for real.

Item 1: answers of both kinds in a row (accepted, refused, refused, accepted; the node used
to log them from one call site at two severities, which rclpy refuses: the node died with
``Logger severity cannot be changed between calls`` and the caller got no reply).
Item 2: ``contact_force_on`` / ``contact_force_off`` changed live apply to the next frames
(they were logged as applied and ignored: the stage kept the values of its reference).
"""
from __future__ import annotations

import time

import pytest

from ros_harness import BAGS, Probe, next_domain_id, running_node

pytestmark = [pytest.mark.ros, pytest.mark.slow]


class TouchSession:
    """The probe's view of a decoder in /tactile: contact messages, references, services."""

    def __init__(self, probe: Probe) -> None:
        from geometry_msgs.msg import PoseStamped
        from rclpy.parameter_client import AsyncParameterClient
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from std_srvs.srv import Trigger

        from tactile_sl_msgs.msg import Contact

        self.probe = probe
        self.contacts: list = []       # (arrival ns, stamp ns, in_contact, normal, max_depth)
        self.references = 0
        qos = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
        probe.node.create_subscription(Contact, "/tactile/contact", self._on_contact, qos)
        # pad_pose is latched (transient local), once per reference: a volatile subscriber
        # not yet matched when the first reference is announced (~0.5 s after the node's
        # publishers appear) would never count it
        probe.node.create_subscription(
            PoseStamped, "/tactile/pad_pose", self._on_pose,
            QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.tare_client = probe.node.create_client(Trigger, "/tactile/tare")
        self.params = AsyncParameterClient(probe.node, "/tactile/decoder")
        self.trigger = Trigger

    def _on_contact(self, msg) -> None:
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        self.contacts.append((time.time_ns(), stamp, bool(msg.in_contact),
                              float(msg.normal_force), float(msg.max_depth)))

    def _on_pose(self, _msg) -> None:
        self.references += 1

    def wait(self, predicate, timeout: float, what: str) -> None:
        assert self.probe.spin_until(predicate, timeout), what

    def phase_start(self, pressed: bool, timeout: float = 20.0) -> None:
        """Wait for the first output of the next pressed (or untouched) phase.

        Outputs of frames that waited for a reference arrive late, when the node is already
        further on, interleaved with the fresh ones (a few per frame): the output before
        must be fresh too (stamped less than 1 s before it arrived), or a stale one before
        a fresh one would pass for a phase change.  The phase's first output must arrive
        within half a phase (0.5 s) of its stamp, so that what the caller does next (a
        tare) still reaches the node in that phase on a loaded machine.
        """
        def pressed_now(c) -> bool:
            return c[4] > 1e-4                   # 0.5 N presses in by about 0.2 mm

        def within(c, seconds: float) -> bool:
            return c[0] - c[1] < seconds * 1e9
        seen = len(self.contacts)
        self.wait(lambda: any(pressed_now(a) != pressed and pressed_now(b) == pressed
                              and within(a, 1.0) and within(b, 0.5)
                              for a, b in zip(self.contacts[seen - 1 if seen else 0:],
                                              self.contacts[seen:])),
                  timeout, f"no {'pressed' if pressed else 'untouched'} phase began")

    def tare(self) -> tuple[bool, str]:
        future = self.tare_client.call_async(self.trigger.Request())
        self.wait(future.done, 15.0, "no answer from tare")
        return future.result().success, future.result().message

    def set(self, **values) -> tuple[int, int]:
        """Set decoder parameters; the wall-clock times of request and answer."""
        from rclpy.parameter import Parameter

        requested = time.time_ns()
        future = self.params.set_parameters([Parameter(k, value=v) for k, v in values.items()])
        self.wait(future.done, 15.0, "no answer from set_parameters")
        assert all(r.successful for r in future.result().results), future.result()
        return requested, time.time_ns()


def test_tare_answers_both_ways_and_contact_thresholds_apply_live(tmp_path):
    from tactile_sl_decoder.tooling.touch_soak import ContactCheck, Thresholds, write_phase_bag

    bag = tmp_path / "phases.mcap"
    write_phase_bag(BAGS / "touch_halfspace.mcap", bag, untouched=[0], pressed=[2, 3],
                    untouched_frames=10, pressed_frames=10)
    domain = next_domain_id()
    with Probe("touch_live", domain) as probe, \
            running_node("tactile_sl_decoder", "decoder", domain,
                         ["-r", "__ns:=/tactile", "-p", "warn_period:=0.0"],
                         tmp_path / "decoder.log") as decoder, \
            running_node("tactile_sl_camera", "replay", domain,
                         ["-r", "__ns:=/tactile", "-p", f"bag:={bag}", "-p", "loop:=true",
                          "-p", "wait_for_subscribers:=1"], tmp_path / "replay.log"):
        s = TouchSession(probe)
        assert s.tare_client.wait_for_service(timeout_sec=30.0), decoder.log()
        s.wait(lambda: s.references >= 1 and s.contacts, 60.0, "no reference: " + decoder.log())

        # item 1: accepted, refused, refused, accepted -- every call answered, node alive
        answers = []
        for pressed in (False, True, None, False):
            if pressed is not None:
                s.phase_start(pressed)
            answers.append(s.tare())
            if answers[-1][0]:
                s.wait(lambda n=s.references: s.references > n, 30.0, "no new reference")
        assert [ok for ok, _ in answers] == [True, False, False, True], answers
        assert all("refused: the pad is touched" in text for ok, text in answers if not ok)
        assert decoder.process.poll() is None and "FATAL" not in decoder.log(), decoder.log()

        # item 2: 0.5 N frames are out of contact with on 1 N / off 0.3 N; held after 2 N
        s.phase_start(pressed=False)
        check = ContactCheck(Thresholds(0.010, 0.005))
        check.change(Thresholds(1.0, 0.3), *s.set(contact_force_on=1.0, contact_force_off=0.3))
        first = len(s.contacts)
        s.phase_start(pressed=True)
        s.phase_start(pressed=False)
        for arrived, stamp, in_contact, normal, _ in s.contacts[first:]:
            check.check(stamp, arrived, in_contact, normal)
        light = [c for c in s.contacts[first:] if 0.3 < c[3] < 1.0 and c[1] > check.changes[0]
                 .answered_ns and not c[2]]
        assert check.violations == [], check.violations
        assert light, "no 0.5 N frame was out of contact under on 1 N / off 0.3 N"
        assert decoder.process.poll() is None, decoder.log()


def test_a_pressed_reference_is_a_warning(ros, domain_id, tmp_path):
    """Item 8: a reference taken while 2 N pressed (190 um RMS fit residual) was one INFO
    line; the wrench then read the load with nothing pressing.  Now a WARN line (and the
    diagnostics' touch status says WARN, docs/diagnostics.md)."""
    from tactile_sl_decoder.tooling.touch_soak import write_phase_bag

    bag = tmp_path / "pressed_first.mcap"
    write_phase_bag(BAGS / "touch_halfspace.mcap", bag, untouched=[3], pressed=[0],
                    untouched_frames=2, pressed_frames=1)
    decoder = ros.start()
    with running_node("tactile_sl_camera", "replay", domain_id,
                      ["-r", "__ns:=/tactile", "-p", f"bag:={bag}",
                       "-p", "wait_for_subscribers:=1", "-p", "rate:=0.5"],
                      tmp_path / "replay.log"):
        assert decoder.wait_for_log("fit residual", 60.0, lambda: ros.spin(0.05)), \
            decoder.log()
    line = next(li for li in decoder.lines() if "fit residual" in li)
    assert line.startswith("[WARN]") and "touched when the reference was taken" in line, line
