"""The viewer in a real browser: what the page shows is what the decoder published.

replay (touch_halfspace, looping slowly) -> decoder -> viewer, and headless Chromium (the
distribution's, driven by playwright) on the viewer's page.  For every frame the page
shows (its stamp is ``body[data-stamp]``), the displayed normal force equals -force.z of the
``wrench`` published with that stamp, to the page's three decimals; and the pressure map
of an untouched frame differs from that of a pressed one.  The viewer's port is chosen by
the system (``port:=0``) and read from its log.

``TACTILE_SL_VIEWER_SCREENSHOT=docs/viewer.png`` also writes the README's screenshot of a
pressed frame there (always to the test's own folder).
"""
from __future__ import annotations

import os
import re
import time

import pytest

from ros_harness import BAGS, REPO, Probe, browser_page, next_domain_id, running_node

pytestmark = [pytest.mark.ros, pytest.mark.slow]

NS = ["-r", "__ns:=/tactile"]
PAGE_STATE = """() => ({
  stamp: document.body.dataset.stamp,
  normal: document.getElementById('normal-force').textContent,
  kind: document.getElementById('map').dataset.kind,
})"""


def _stamp_ns(text: str) -> int:
    sec, nanosec = text.split(".")
    return int(sec) * 1_000_000_000 + int(nanosec)


def test_page_shows_the_published_force_and_a_pressure_map_that_follows_the_touch(tmp_path):
    from geometry_msgs.msg import WrenchStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    domain = next_domain_id()
    wrenches: dict[int, float] = {}
    with Probe("viewer_test", domain) as probe, \
            running_node("tactile_sl_decoder", "decoder", domain,
                         [*NS, "-p", "warn_period:=0.0"], tmp_path / "decoder.log"), \
            running_node("tactile_sl_viewer", "viewer", domain,
                         [*NS, "-p", "port:=0"], tmp_path / "viewer.log") as viewer:
        probe.node.create_subscription(
            WrenchStamped, "/tactile/wrench",
            lambda m: wrenches.__setitem__(
                m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec,
                m.wrench.force.z),
            QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
        assert viewer.wait_for_log("viewer: open http", 30.0), viewer.log()
        url = re.search(r"open (http://\S+/)", viewer.log()).group(1)
        assert url.startswith("http://127.0.0.1:")          # loopback by default
        with browser_page(tmp_path / "profile") as page:
            errors: list[str] = []
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            page.goto(url)
            assert viewer.wait_for_log("a page is open: subscribed", 10.0), viewer.log()
            shown = _watch(page, probe, domain, tmp_path, wrenches)
            assert not errors, errors
    compared = {s: v for s, v in shown.items() if s in wrenches and v["normal"] != "–"}
    assert len(compared) >= 4, ([(s, v["normal"]) for s, v in shown.items()], sorted(wrenches))
    for stamp, seen in compared.items():
        assert float(seen["normal"]) == pytest.approx(-wrenches[stamp], abs=0.0006), stamp
    light = min(compared, key=lambda s: abs(wrenches[s]))
    pressed = max(compared, key=lambda s: -wrenches[s])
    assert abs(wrenches[light]) < 0.1 and -wrenches[pressed] > 1.0, wrenches
    assert compared[light]["map"] != compared[pressed]["map"]
    assert compared[pressed]["in_contact"] == "yes"


def _watch(page, probe, domain: int, tmp_path, wrenches: dict[int, float]) -> dict:
    """Replay the bag eight times slowly; what the page shows for each stamp it shows."""
    shown: dict[int, dict] = {}
    screenshot = os.environ.get("TACTILE_SL_VIEWER_SCREENSHOT")
    shot = None
    steady = time.monotonic() + 6.0        # a picture without the reference's start-up too
    with running_node("tactile_sl_camera", "replay", domain, [
            *NS, "-p", f"bag:={BAGS / 'touch_halfspace.mcap'}", "-p", "loop:=true",
            "-p", "loops:=8", "-p", "rate:=0.5", "-p", "wait_for_subscribers:=1",
            "-p", "wait_for_subscribers_timeout:=30.0"], tmp_path / "replay.log") as replay:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and replay.process.poll() is None:
            probe.spin(0.03)
            state = page.evaluate(PAGE_STATE)
            if not state["stamp"]:
                continue
            stamp = _stamp_ns(state["stamp"])
            if stamp in shown:
                continue
            # read the canvas and the table of the frame on screen (the page draws a frame
            # whole before it sets data-stamp; it may have moved on: then skip this one)
            picture = page.evaluate("""() => [document.body.dataset.stamp,
                document.getElementById('map').toDataURL(),
                document.getElementById('in-contact').textContent]""")
            if picture[0] != state["stamp"]:
                continue
            shown[stamp] = {**state, "map": picture[1], "in_contact": picture[2]}
            if state["normal"] != "–" and float(state["normal"]) > 1.5 \
                    and (shot is None or steady < time.monotonic() < steady + 60.0):
                picture_file = tmp_path / f"viewer_{stamp}.png"
                page.screenshot(path=str(picture_file), full_page=True)
                if page.evaluate("document.body.dataset.stamp") == state["stamp"]:
                    shot = picture_file              # still that pressed frame: keep it
                    steady = steady + 60.0 if time.monotonic() > steady else steady
        probe.spin(1.0)                                   # the last wrenches
    assert shot is not None, f"no pressed frame was shown: {shown}"
    if screenshot:
        target = REPO / screenshot
        tmp = target.with_suffix(".tmp.png")
        tmp.write_bytes(shot.read_bytes())
        tmp.replace(target)
    return shown
