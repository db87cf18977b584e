"""``viewer``: the decoder's outputs in a browser, at the browser's pace (read-only).

Subscribes (relative names; only while a page is open, and ``linger`` seconds after)::

    left/image_raw           sensor_msgs/Image            (sensor data QoS)
    left/symbols_decoded     tactile_sl_msgs/SymbolArray  (the decoder builds it only then)
    points, field            sensor_msgs/PointCloud2
    wrench                   geometry_msgs/WrenchStamped
    contact                  tactile_sl_msgs/Contact
    depth                    sensor_msgs/Image (32FC1)
    slip                     tactile_sl_msgs/Slip         (when this build has the message)
    /diagnostics             diagnostic_msgs/DiagnosticArray

and serves one page on ``http://host:port/`` (default 127.0.0.1:8080), at most ``max_rate``
frames a second to each page (default 10).  Every subscription
is best effort with a short queue: the decoder's reliable publishers never wait for this
node, and a callback only files the message by stamp (:mod:`tactile_sl_viewer.assembly`);
converting and encoding happen when a page asks for the next frame
(:mod:`tactile_sl_viewer.web`).
Parameters: ``config/viewer.yaml``.
"""
from __future__ import annotations

import time
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, PointCloud2

from tactile_sl_common.nodes.parameters import LiveParameters
from tactile_sl_common.nodes.runner import run_node
from tactile_sl_decoder.pattern import default_pattern_path, load_pattern
from tactile_sl_msgs.msg import Contact, SymbolArray
from tactile_sl_viewer.assembly import FrameAssembler
from tactile_sl_viewer.packets import PacketBuilder
from tactile_sl_viewer.view_model import PadGeometry, stamp_of
from tactile_sl_viewer.web import ViewerServer

try:     # the slip output is being added on another branch: shown when the type exists
    from tactile_sl_msgs.msg import Slip
except ImportError:
    Slip = None


def pad_geometry(pattern_file: str) -> PadGeometry:
    """Rows, columns and pitch of the printed pattern (the shipped one when empty)."""
    pattern = load_pattern(pattern_file or default_pattern_path(), verify=False)
    rows, cols = pattern.array.shape
    return PadGeometry(int(rows), int(cols), float(pattern.pitch_m))


class LiveSource:
    """What the server needs from the node: the assembler and the page's greeting."""

    def __init__(self, assembler: FrameAssembler, namespace: str) -> None:
        self.assembler = assembler
        self.namespace = namespace

    def hello(self) -> dict[str, Any]:
        return {"mode": "live", "namespace": self.namespace, "slip": Slip is not None}

    def seek(self, index: int) -> None:
        """A live stream has no frames to seek to."""

    def extra(self) -> dict[str, Any]:
        return {}


class ViewerNode(Node):
    """Files the decoder's messages by stamp; the web server shows the newest frame."""

    def __init__(self) -> None:
        super().__init__("viewer")
        self.params = LiveParameters(self)
        decl = self.params.declare
        host = str(decl("host", "127.0.0.1",
            "Address the web server listens on: 127.0.0.1 = this computer only; 0.0.0.0 = "
            "every interface (on a robot, for a laptop on its network).", read_only=True,
            check=lambda v: None if v.strip() else "empty host"))
        port = int(decl("port", 8080, "TCP port of the page (0 = any free port, logged).",
                        (0, 65535), read_only=True))
        max_pages = int(decl("max_pages", 4, "Pages that may be open at once.", (1, 64),
                             read_only=True))
        pattern_file = str(decl("pattern_file", "",
            "Pattern YAML (its rows, columns and pitch place the cells on the pressure map); "
            "empty = the pattern the package ships.", read_only=True))
        self.linger = float(decl("linger", 5.0,
            "Seconds the subscriptions stay after the last page closed (a reload keeps "
            "them); with no page open the node subscribes to nothing.", (0.0, 3600.0),
            apply=lambda v: setattr(self, "linger", float(v))))
        self.builder = PacketBuilder(pad_geometry(pattern_file),
                                     self.get_namespace().strip("/"),
                                     on_error=self._warn)
        self.builder.jpeg_quality = int(decl("jpeg_quality", 80,
            "JPEG quality of the camera image sent to the page.", (10, 100),
            apply=lambda v: setattr(self.builder, "jpeg_quality", int(v))))
        self.builder.min_pressure_scale_kpa = float(decl("min_pressure_scale", 10.0,
            "Smallest top of the pressure colour scale, kPa (an untouched pad stays dark).",
            (0.001, 1e6),
            apply=lambda v: setattr(self.builder, "min_pressure_scale_kpa", float(v))))
        max_rate = float(decl("max_rate", 10.0,
            "Frames a second sent to each page at most (0 = as many as the page asks for); "
            "a request waits until the page's next frame is due, then the newest frame goes "
            "(the ones between are dropped). The cap keeps a browser on the sensor's own "
            "computer from drawing frames the decoder needs the CPU for.", (0.0, 1000.0),
            apply=lambda v: setattr(self.server, "max_rate", float(v))))
        self.assembler = FrameAssembler()
        self.source = LiveSource(self.assembler, self.get_namespace())
        self.server = ViewerServer(self.source, self.builder, host, port, max_pages,
                                   max_rate=max_rate)
        self._subscriptions: list[Any] = []
        self._last_page = -1e9
        self._last_warn = -1e9
        url = self.server.start()
        self.create_timer(0.25, self._follow_pages)
        self.get_logger().info(f"viewer: open {url} (namespace {self.get_namespace()}"
                               f"{'' if Slip is not None else '; no Slip message in this build'})")

    def destroy_node(self) -> None:
        """Close the pages and the web server before the node goes."""
        self.server.stop()
        super().destroy_node()

    def _warn(self, text: str) -> None:
        now = time.monotonic()
        if now - self._last_warn > 5.0:
            self._last_warn = now
            self.get_logger().warning(f"a message could not be shown: {text}")

    def _follow_pages(self) -> None:
        """Subscribe while a page is open (and ``linger`` s after); else subscribe nothing."""
        now = time.monotonic()
        if self.server.clients:
            self._last_page = now
        wanted = now - self._last_page <= self.linger
        if wanted and not self._subscriptions:
            self._subscribe()
            self.get_logger().info("a page is open: subscribed")
        elif not wanted and self._subscriptions:
            for sub in self._subscriptions:
                self.destroy_subscription(sub)
            self._subscriptions = []
            self.get_logger().info("no page open: unsubscribed")

    def _filer(self, part: str) -> Any:
        """The callback of one part: file the message under its stamp (nothing else)."""
        add = self.assembler.add
        return lambda msg: add(part, msg, stamp_of(msg))

    def _subscribe(self) -> None:
        newest = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                            reliability=ReliabilityPolicy.BEST_EFFORT)
        topics: list[tuple[str, Any, str]] = [
            ("image", Image, "left/image_raw"), ("glyphs", SymbolArray, "left/symbols_decoded"),
            ("points", PointCloud2, "points"), ("field", PointCloud2, "field"),
            ("wrench", WrenchStamped, "wrench"), ("contact", Contact, "contact"),
            ("depth", Image, "depth")]
        if Slip is not None:
            topics.append(("slip", Slip, "slip"))
        for part, kind, topic in topics:
            self._subscriptions.append(self.create_subscription(
                kind, topic, self._filer(part), newest))
        self._subscriptions.append(self.create_subscription(
            DiagnosticArray, "/diagnostics", self.assembler.add_diagnostics, newest))


def main(args: list[str] | None = None) -> None:
    """Entry point of the ``viewer`` executable."""
    run_node(ViewerNode, "viewer", args=args)


if __name__ == "__main__":
    main()
