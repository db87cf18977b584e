"""Soak of the decoder's touch outputs: tares accepted and refused, settings changed live.

The installed ``decoder`` and a looping ``replay`` run as separate processes (namespace
/tactile, loopback DDS, domain ``--domain-id``: BENCH_DOMAIN_ID by default). The replay
loops a bag built from ``bags/touch_halfspace.mcap`` (tooling/touch_soak.py): 2 s of the
untouched pad, then 2 s pressed (its 0.5 N, 2 N and 2 N + shear frames). So the pad really
is pressed in half of the time, by 0.2-0.85 mm, far above ``tare_max_depth``:

* every ``--tare-period`` s (2) a ``tare``, alternately early in an untouched phase
  (expected: accepted, and a new reference follows) and in a pressed one (expected: refused
  because the pad is touched); each answer is checked against the stage's rule applied to
  the last contact message seen before the call;
* every ``--param-period`` s (3) ``contact_force_on`` / ``contact_force_off`` and
  ``tare_max_depth`` change live (a cycle of settings that put 0.5 N and 2 N on either
  side of the thresholds and inside the hysteresis band);
* every ``contact`` message's ``in_contact`` is checked against the hysteresis with the
  thresholds in force (tooling/touch_soak.ContactCheck);
* the decoder must stay alive; its resident memory is sampled every 10 s.

Prints the figures and exits 1 on any failure. Not part of ``make test`` (minutes); a
short run: ``python tools/soak_touch.py --seconds 30``.

    nice -n 10 python tools/soak_touch.py              # 5 minutes
"""
from __future__ import annotations

import argparse
import os
import pathlib
import subprocess
import sys
import time
from dataclasses import dataclass

import rclpy
from geometry_msgs.msg import PoseStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_srvs.srv import Trigger

from tactile_sl_decoder.tooling.touch_soak import (
    ContactCheck,
    Thresholds,
    tare_expected,
    write_phase_bag,
)
from tactile_sl_msgs.msg import Contact

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from ros_harness import executable, ros_env, stop  # noqa: E402

# (contact_force_on, contact_force_off, tare_max_depth): 0.5 N and 2 N frames above, below
# and between the thresholds; tare_max_depth always far below the pressed indentation
SETTINGS = [(0.010, 0.005, 5e-5), (1.0, 0.3, 1e-4), (0.3, 0.04, 3e-5), (1.0, 0.6, 5e-5),
            (3.0, 1.0, 1e-4), (0.05, 0.02, 5e-5)]
PRESSED_DEPTH = 1e-4    # m: a contact message of the pressed phase (0.5 N: 0.2 mm)


@dataclass
class Seen:
    arrived_ns: int
    stamp_ns: int
    in_contact: bool
    normal_force: float
    max_depth: float

    @property
    def pressed(self) -> bool:
        return self.max_depth > PRESSED_DEPTH

    @property
    def fresh(self) -> bool:
        """Stamped (published by the replay) less than 1 s before it arrived here."""
        return self.arrived_ns - self.stamp_ns < 10**9


def _rss_mb(pid: int) -> float:
    try:
        status = pathlib.Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return float("nan")
    return next((int(line.split()[1]) / 1024.0 for line in status.splitlines()
                 if line.startswith("VmRSS:")), float("nan"))


class Soak:
    """The probe node, the live checks and the schedule."""

    def __init__(self, domain: int, decoder: subprocess.Popen) -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node("soak_touch", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.decoder = decoder
        self.seen: list[Seen] = []
        self.references = 0
        self.reference_index = 0
        reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.node.create_subscription(Contact, "/tactile/contact", self._on_contact, reliable)
        self.node.create_subscription(PoseStamped, "/tactile/pad_pose", self._on_pose,
                                      QoSProfile(depth=10,
                                                 reliability=ReliabilityPolicy.RELIABLE))
        self.tare_client = self.node.create_client(Trigger, "/tactile/tare")
        self.params = AsyncParameterClient(self.node, "/tactile/decoder")
        on, off, depth = SETTINGS[0]
        self.check = ContactCheck(Thresholds(on, off))
        self.current = Thresholds(on, off)
        self.tare_max_depth = depth
        self.setting = 0
        self.next_setting_at = 0.0
        self.param_period = 3.0
        self.failures: list[str] = []
        self.tares = {"accepted": 0, "refused": 0, "mismatched": 0}

    def _on_contact(self, msg: Contact) -> None:
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        seen = Seen(time.time_ns(), stamp, bool(msg.in_contact), float(msg.normal_force),
                    float(msg.max_depth))
        self.seen.append(seen)
        self.check.check(seen.stamp_ns, seen.arrived_ns, seen.in_contact, seen.normal_force)

    def _on_pose(self, _msg: PoseStamped) -> None:
        self.references += 1
        self.reference_index = len(self.seen)     # contact messages from here: new reference

    def alive(self) -> bool:
        return self.decoder.poll() is None

    def spin(self, seconds: float) -> None:
        """Handle callbacks (and the live setting changes when due) for ``seconds``."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)
            if self.next_setting_at and time.monotonic() >= self.next_setting_at:
                self.change_setting()

    def wait(self, predicate, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end and self.alive():
            if predicate():
                return True
            self.spin(0.02)
        return bool(predicate())

    def _call(self, future, timeout: float = 15.0):
        end = time.monotonic() + timeout
        while not future.done() and time.monotonic() < end and self.alive():
            self.executor.spin_once(timeout_sec=0.02)
        return future.result() if future.done() else None

    def change_setting(self) -> None:
        """The next (on, off, tare_max_depth) of the cycle, set live and recorded."""
        self.next_setting_at = time.monotonic() + self.param_period
        self.setting = (self.setting + 1) % len(SETTINGS)
        on, off, depth = SETTINGS[self.setting]
        # each parameter is applied (and validated) on its own: raising on, set it first;
        # lowering it, set off first, so that off never exceeds on in between
        order = ([("contact_force_on", on), ("contact_force_off", off)]
                 if on >= self.current.on else
                 [("contact_force_off", off), ("contact_force_on", on)])
        requested = time.time_ns()
        future = self.params.set_parameters(
            [Parameter(name, value=value) for name, value in order]
            + [Parameter("tare_max_depth", value=depth)])
        result = self._call(future)
        answered = time.time_ns()
        if result is None or not all(r.successful for r in result.results):
            self.failures.append(f"set_parameters on {on} / off {off}: "
                                 f"{result.results if result else 'no answer'}")
            return
        self.check.change(Thresholds(on, off), requested, answered)
        self.current = Thresholds(on, off)
        self.tare_max_depth = depth

    def phase_begins(self, pressed: bool, timeout: float = 12.0) -> bool:
        """Wait for the first output of a pressed (or untouched) phase.

        It must arrive after this call, be made with the latest reference and be fresh
        (outputs of frames that waited for a reference arrive late, when the node's last
        frame is already another).
        """
        start = max(len(self.seen), self.reference_index)
        return self.wait(lambda: any(a.pressed != pressed and b.pressed == pressed
                                     and b.fresh
                                     for a, b in zip(self.seen[max(start - 1, 0):],
                                                     self.seen[start:])), timeout)

    def tare(self) -> None:
        """Call tare and check the answer against the rule on the last frame seen."""
        last = self.seen[-1]
        expected = tare_expected(last.in_contact, last.max_depth, self.tare_max_depth)
        result = self._call(self.tare_client.call_async(Trigger.Request()))
        if result is None:
            self.failures.append("tare: no answer" + ("" if self.alive() else
                                                      " (the decoder died)"))
            return
        self.tares["accepted" if result.success else "refused"] += 1
        if result.success != expected:
            self.tares["mismatched"] += 1
            self.failures.append(f"tare {'accepted' if result.success else 'refused'} after "
                                 f"a frame with in_contact {last.in_contact}, depth "
                                 f"{last.max_depth * 1e6:.0f} um (tare_max_depth "
                                 f"{self.tare_max_depth * 1e6:.0f} um): {result.message}")
        if result.success:
            self.check.reset()

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def main() -> int:  # noqa: C901 - one soak run: processes, schedule, report
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=300.0)
    parser.add_argument("--tare-period", type=float, default=2.0,
                        help="seconds between tares: the length of each phase (untouched, "
                        "pressed) of the looped bag, which plays at 10 Hz")
    parser.add_argument("--param-period", type=float, default=3.0,
                        help="seconds between live changes of the touch settings")
    parser.add_argument("--domain-id", type=int,
                        default=int(os.environ.get("BENCH_DOMAIN_ID", 29)))
    parser.add_argument("--logs", type=pathlib.Path, default=REPO / "out" / "soak_touch")
    args = parser.parse_args()
    args.logs.mkdir(parents=True, exist_ok=True)
    bag = args.logs / "phases.mcap"
    phase = max(5, round(args.tare_period * 10))
    frames = write_phase_bag(REPO / "bags" / "touch_halfspace.mcap", bag, untouched=[0],
                             pressed=[2, 3, 4], untouched_frames=phase, pressed_frames=phase)
    env = ros_env(args.domain_id)
    with open(args.logs / "decoder.log", "w") as dlog, open(args.logs / "replay.log", "w") as rlog:
        decoder = subprocess.Popen(
            [str(executable("tactile_sl_decoder", "decoder")), "--ros-args",
             "-r", "__ns:=/tactile", "-p", "warn_period:=0.0"],
            env=env, stdout=dlog, stderr=subprocess.STDOUT)
        replay = subprocess.Popen(
            [str(executable("tactile_sl_camera", "replay")), "--ros-args", "-r",
             "__ns:=/tactile", "-p", f"bag:={bag}", "-p", "loop:=true",
             "-p", "wait_for_subscribers:=1"], env=env, stdout=rlog, stderr=subprocess.STDOUT)
    soak = Soak(args.domain_id, decoder)
    soak.param_period = args.param_period
    rss: list[tuple[float, float]] = []
    try:
        if not soak.tare_client.wait_for_service(timeout_sec=60.0) or not soak.wait(
                lambda: soak.references >= 1 and len(soak.seen) >= 3, 90.0):
            print("soak: the decoder gave no touch outputs (see out/soak_touch/decoder.log)")
            return 1
        t0 = time.monotonic()
        rss.append((0.0, _rss_mb(decoder.pid)))
        soak.next_setting_at = t0 + args.param_period
        next_rss = t0 + 10.0
        want_accept = True
        while time.monotonic() - t0 < args.seconds and soak.alive():
            # at the start of each phase: early in an untouched one a tare must be accepted,
            # in a pressed one (seen through the latest reference) refused
            if soak.phase_begins(pressed=not want_accept, timeout=6 * args.tare_period + 10):
                soak.tare()
            else:
                soak.failures.append(f"no {'untouched' if want_accept else 'pressed'} phase "
                                     f"began in time")
            want_accept = not want_accept
            if time.monotonic() >= next_rss:
                rss.append((time.monotonic() - t0, _rss_mb(decoder.pid)))
                next_rss += 10.0
        duration = time.monotonic() - t0
        soak.next_setting_at = 0.0         # the last accepted tare's reference, if still due
        soak.wait(lambda: soak.references >= soak.tares["accepted"] + 1, 15.0)
        rss.append((duration, _rss_mb(decoder.pid)))
        alive = soak.alive()
    finally:
        soak.close()
        code_replay = stop(replay)
        code_decoder = stop(decoder)
    check = soak.check
    failures = soak.failures + check.violations
    if not alive:
        failures.append(f"the decoder exited (status {decoder.returncode}) during the soak")
    if soak.references != soak.tares["accepted"] + 1:
        failures.append(f"{soak.references} references announced for "
                        f"{soak.tares['accepted']} accepted tares (+1 at start)")
    fatal = [line for line in (args.logs / "decoder.log").read_text().splitlines()
             if "FATAL" in line or "Traceback" in line]
    failures += fatal
    print(f"soak: {duration:.0f} s, a bag of {frames} frames looped at 10 Hz ({phase / 10:g} s "
          f"untouched, {phase / 10:g} s pressed)")
    print(f"  contact messages checked: {check.checked} (hysteresis held between off and on: "
          f"{check.held}; during a change in flight, either setting accepted: {check.either}); "
          f"violations: {len(check.violations)}")
    print(f"  tares: {soak.tares['accepted']} accepted, {soak.tares['refused']} refused, "
          f"{soak.tares['mismatched']} against the rule; references announced: "
          f"{soak.references}")
    print(f"  live setting changes: {len(check.changes)} (contact_force_on/off, "
          f"tare_max_depth)")
    print(f"  decoder alive at the end: {alive}; exit status after SIGTERM: {code_decoder} "
          f"(replay {code_replay})")
    print("  decoder resident memory (MB) every ~10 s: "
          + ", ".join(f"{t:.0f}s {m:.1f}" for t, m in rss))
    if len(rss) >= 3:
        first, last = rss[1][1], rss[-1][1]       # from 10 s on: after the first references
        print(f"  resident memory: {rss[0][1]:.1f} MB at start, {first:.1f} MB at "
              f"{rss[1][0]:.0f} s, {last:.1f} MB at the end ({last - first:+.1f} MB since "
              f"{rss[1][0]:.0f} s)")
    for line in failures[:20]:
        print(f"  FAIL: {line}")
    print("soak: PASS" if not failures else f"soak: FAIL ({len(failures)} problem(s))")
    return 0 if not failures else 1


if __name__ == "__main__":
    sys.exit(main())
