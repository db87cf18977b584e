"""Publishes :class:`~.diagnostics.Status` records on ``/diagnostics`` (DiagnosticArray).

The diagnostic_updater package is not available as a wheel; this is the part of it the
decoder needs: a timer that asks for the statuses of the last period and publishes them as
one diagnostic_msgs/DiagnosticArray on the absolute topic ``/diagnostics`` (reliable, depth
10, as diagnostic_updater, diagnostic_aggregator and rqt_robot_monitor use it).  Status names
are ``<node's full name without the leading slash>: <task>``, e.g. ``tactile/decoder: coverage``;
``hardware_id`` names the sensor (its frame prefix or namespace).
"""
from __future__ import annotations

from typing import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import QoSProfile

from .diagnostics import Status


def to_message(status: Status, prefix: str, hardware_id: str) -> DiagnosticStatus:
    """DiagnosticStatus of one record."""
    msg = DiagnosticStatus()
    msg.level = bytes([int(status.level)])
    msg.name = f"{prefix}: {status.name}"
    msg.message = status.message
    msg.hardware_id = hardware_id
    msg.values = [KeyValue(key=k, value=v) for k, v in status.values.items()]
    return msg


class DiagnosticsPublisher:
    """Calls ``collect()`` every ``period_s`` and publishes what it returns."""

    def __init__(self, node: Node, collect: Callable[[], list[Status]], period_s: float,
                 hardware_id: str, qos: QoSProfile | None = None) -> None:
        self.node = node
        self.collect = collect
        self.hardware_id = hardware_id
        self.prefix = node.get_fully_qualified_name().lstrip("/")
        self.pub = node.create_publisher(DiagnosticArray, "/diagnostics",
                                         qos or QoSProfile(depth=10))
        self.timer = node.create_timer(period_s, self.publish)

    def publish(self) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.status = [to_message(s, self.prefix, self.hardware_id) for s in self.collect()]
        self.pub.publish(msg)
