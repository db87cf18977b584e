"""The decoder node's touch outputs: parameters, publishers, the ``tare`` service, pad pose.

Publishes (relative names, reliable, depth 5; pad frame): ``field`` (PointCloud2),
``wrench`` (WrenchStamped), ``contact`` (tactile_sl_msgs/Contact), ``depth`` (Image 32FC1),
``slip`` (tactile_sl_msgs/Slip), ``slip_markers`` (visualization_msgs/MarkerArray, for RViz),
and ``pad_pose`` (PoseStamped of the pad frame in the left optical frame, transient local,
plus ``/tf_static`` when tf2_ros is importable, i.e. on a system ROS install).  The work is
the node's :class:`~tactile_sl_decoder.sensor_step.SensorStep` (its
:class:`~tactile_sl_decoder.touch.driver.TouchDriver`); message fields come from
:mod:`tactile_sl_decoder.touch.messages`, the same dicts ``tactile-sl replay`` writes.
"""
from __future__ import annotations

import array
from typing import Any, Callable

from geometry_msgs.msg import Point, PoseStamped, Vector3, WrenchStamped
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import Image, PointCloud2
from std_msgs.msg import ColorRGBA
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from tactile_sl_common.nodes.messages import apply_header, cloud_msg, image_msg
from tactile_sl_common.nodes.parameters import LiveParameters, declare_qos
from tactile_sl_decoder.touch.driver import ReferenceReady, TouchDriver, TouchFrame
from tactile_sl_decoder.touch.messages import (
    contact_fields,
    depth_fields,
    field_fields,
    pose_fields,
    slip_fields,
    slip_markers,
    wrench_fields,
)
from tactile_sl_decoder.touch.reference import residual_warning
from tactile_sl_decoder.touch.stage import TouchResult

try:
    from tactile_sl_msgs.msg import Contact, Slip
except ImportError:  # pragma: no cover - interfaces not built
    Contact = Slip = None

try:  # only on a system ROS install (tf2_ros is not a wheel)
    from geometry_msgs.msg import TransformStamped
    from tf2_ros.static_transform_broadcaster import StaticTransformBroadcaster
except ImportError:
    StaticTransformBroadcaster = None


CATCH_UP_BURST = 3
"""Frames of a reference's backlog published per wake-up (see TouchOutputs.publish)."""


def _vec(cls: Any, d: dict[str, float]) -> Any:
    return cls(x=d["x"], y=d["y"], z=d["z"])


def wrench_msg(fields: dict[str, Any]) -> WrenchStamped:
    """WrenchStamped from :func:`~tactile_sl_decoder.touch.messages.wrench_fields`."""
    msg = WrenchStamped()
    apply_header(msg, fields)
    msg.wrench.force = _vec(Vector3, fields["wrench"]["force"])
    msg.wrench.torque = _vec(Vector3, fields["wrench"]["torque"])
    return msg


def contact_msg(fields: dict[str, Any]) -> Any:
    """Contact from :func:`~tactile_sl_decoder.touch.messages.contact_fields`."""
    msg = Contact()
    apply_header(msg, fields)
    for key in ("in_contact", "area", "max_depth", "normal_force", "peak_pressure",
                "cells_in_contact"):
        setattr(msg, key, fields[key])
    msg.centroid = _vec(Point, fields["centroid"])
    msg.shear_force = _vec(Vector3, fields["shear_force"])
    msg.region_force = array.array("d", fields["region_force"])
    msg.region_area = array.array("d", fields["region_area"])
    msg.region_centroid = [_vec(Point, c) for c in fields["region_centroid"]]
    return msg


def slip_msg(fields: dict[str, Any]) -> Any:
    """Slip from :func:`~tactile_sl_decoder.touch.messages.slip_fields`."""
    msg = Slip()
    apply_header(msg, fields)
    for key in ("state", "stick_ratio", "slip_margin", "friction_coefficient", "contact_radius",
                "stick_radius", "normal_force", "tangential_force", "fit_residual"):
        setattr(msg, key, fields[key])
    msg.direction = _vec(Vector3, fields["direction"])
    msg.centroid = _vec(Point, fields["centroid"])
    return msg


def markers_msg(markers: list[dict[str, Any]], fields: dict[str, Any]) -> MarkerArray:
    """MarkerArray from :func:`~tactile_sl_decoder.touch.messages.slip_markers`.

    The markers take the header of ``fields`` (the slip message's) and namespace ``slip``.
    """
    out = MarkerArray()
    for m in markers:
        msg = Marker()
        apply_header(msg, fields)
        msg.ns, msg.id, msg.type, msg.action = "slip", m["id"], m["type"], m["action"]
        if "position" in m:
            msg.pose.position = _vec(Point, m["position"])
            o = m["orientation"]
            msg.pose.orientation.x, msg.pose.orientation.y = o["x"], o["y"]
            msg.pose.orientation.z, msg.pose.orientation.w = o["z"], o["w"]
            msg.scale = _vec(Vector3, m["scale"])
            r, g, b, a = m["color"]
            msg.color = ColorRGBA(r=float(r), g=float(g), b=float(b), a=float(a))
        out.markers.append(msg)
    return out


def pose_msg(fields: dict[str, Any]) -> PoseStamped:
    """PoseStamped from :func:`~tactile_sl_decoder.touch.messages.pose_fields`."""
    msg = PoseStamped()
    apply_header(msg, fields)
    msg.pose.position = _vec(Point, fields["pose"]["position"])
    o = fields["pose"]["orientation"]
    msg.pose.orientation.x, msg.pose.orientation.y = o["x"], o["y"]
    msg.pose.orientation.z, msg.pose.orientation.w = o["z"], o["w"]
    return msg


class TouchOutputs:
    """The touch outputs of the decoder node: publishers, the tare service, the pad pose."""

    def __init__(self, node: Node, live: LiveParameters, driver: TouchDriver, frame_prefix: str,
                 out_qos: QoSProfile, poll: Callable[[], TouchFrame | None]) -> None:
        """Publishers, the tare service and the reference's poll timer.

        ``poll`` installs a reference prepared in the background (SensorStep.poll_touch: its
        outputs come back through :meth:`publish_frame`, or are returned).
        """
        self.node = node
        self.driver = driver
        self._poll = poll
        self.announced_waiting = False
        self.tares = 0             # tares accepted (the reference is taken again)
        self.last_tare = ""        # the answer to the last tare request
        sensor = driver.stage.sensor
        self.frame_id = frame_prefix + sensor.pad_frame
        self.pub_field = node.create_publisher(PointCloud2, "field", out_qos)
        self.pub_wrench = node.create_publisher(WrenchStamped, "wrench", out_qos)
        self.pub_contact = node.create_publisher(Contact, "contact", out_qos)
        self.pub_depth = node.create_publisher(Image, "depth", out_qos)
        self.pub_slip = node.create_publisher(Slip, "slip", out_qos)
        self.pub_markers = node.create_publisher(MarkerArray, "slip_markers", out_qos)
        # the slip estimate only while something listens to it (it is per frame, no history)
        driver.stage.slip_wanted = self._slip_heard
        latched = declare_qos(live, "pad_pose", "pad_pose (latched: late joiners get the pad "
                              "frame)", 1, "reliable", "transient_local")
        self.pub_pose = node.create_publisher(PoseStamped, "pad_pose", latched)
        self.tf = StaticTransformBroadcaster(node) if StaticTransformBroadcaster else None
        node.create_service(Trigger, "tare", self._on_tare)
        # announce (and install) a reference prepared in the background as soon as it is
        # done, and publish its backlog: a 20 Hz timer that looks at two flags otherwise (the
        # touch worker cannot start a timer, and the events executor has no guard conditions)
        self._poll_timer = node.create_timer(0.05, self._poll_reference)
        e = sensor.elastomer
        node.get_logger().info(
            f"touch: E {e.youngs_modulus:.3g} Pa, nu {e.poisson_ratio:.3g}, "
            f"{'half-space' if e.thickness == 0 else f'layer {e.thickness * 1e3:.3g} mm'} "
            f"({sensor.source}); pad frame {self.frame_id}")

    def restarted(self) -> None:
        """The stage was restarted (``mirrored`` changed): a new reference is taken."""
        self.announced_waiting = False
        self.node.get_logger().info("mirrored changed: the touch reference is taken again "
                                    "from the next decoded frames (the pad must be untouched)")

    def _on_tare(self, _request: Any, response: Any) -> Any:
        ok, text = self.driver.tare()
        response.success, response.message = ok, text
        self.tares += int(ok)
        self.last_tare = f"{'accepted' if ok else 'refused'}: {text}"
        # one call site per severity: rclpy refuses a severity change at the same call site
        # (a ValueError in this callback, which ended the node without a reply)
        if ok:
            self.node.get_logger().info(f"tare {text}")
        else:
            self.node.get_logger().warning(f"tare {text}")
        self.announced_waiting = False
        return response

    def _poll_reference(self) -> None:
        """Timer: a reference finished in the background is installed and announced."""
        stage = self.driver.stage
        if not (stage.preparing or stage.caught_up):
            return
        touch = self._poll()
        if touch is not None:
            self.publish(touch)

    def before_frame(self) -> None:
        """Called with each frame's points (executor thread), before the touch stage runs."""
        if not self.driver.ready and not self.announced_waiting:
            self.announced_waiting = True
            self.node.get_logger().info(
                f"touch: no outputs until the reference is taken from "
                f"{self.driver.stage.params.reference_frames} decoded frame(s) of the "
                f"untouched pad")

    def publish_frame(self, touch: TouchFrame, stamp: tuple[int, int] | None) -> None:
        """One frame's touch outputs, after those of frames that waited for the reference.

        Called from the touch worker (SensorStep's ``on_touch``); ``stamp`` None: a poll's.
        """
        if not self.publish(touch):
            return
        if touch.result is not None and stamp is not None:
            self._publish(touch.result, stamp)

    def publish(self, touch: TouchFrame) -> bool:
        """The reference's news and the backlog's next outputs; False if the reference failed.

        The backlog of a reference's preparation (a second's frames) goes out at most
        ``CATCH_UP_BURST`` frames per wake-up (each frame and the 20 Hz timer), so that a
        subscriber's queue (depth 10 is common) does not overflow and lose the oldest.
        """
        if touch.reference_failed is not None:
            self.node.get_logger().warning(
                f"touch: reference not usable ({touch.reference_failed}); trying again "
                f"with the next frames")
            if touch.caught_up:   # after a failure in the timer: the rest of an old backlog
                for stamp, result in touch.caught_up:
                    self._publish(result, stamp)
            return False
        if touch.reference_ready is not None:
            self._announce_reference(touch.reference_ready)
        for stamp, result in touch.caught_up:
            self._publish(result, stamp)
        return True

    def _slip_heard(self) -> bool:
        return bool(self.pub_slip.get_subscription_count()
                    or self.pub_markers.get_subscription_count())

    def _publish(self, result: TouchResult, stamp: tuple[int, int]) -> None:
        """One frame's touch outputs, each built only while something subscribes to it."""
        f = self.frame_id
        if self.pub_field.get_subscription_count():
            self.pub_field.publish(cloud_msg(field_fields(result, stamp, f)))
        if self.pub_wrench.get_subscription_count():
            self.pub_wrench.publish(wrench_msg(wrench_fields(result, stamp, f)))
        if self.pub_contact.get_subscription_count():
            self.pub_contact.publish(contact_msg(contact_fields(result.contact, stamp, f)))
        if self.pub_depth.get_subscription_count():
            self.pub_depth.publish(image_msg(depth_fields(result.depth, stamp, f)))
        if result.slip is not None and (self.pub_slip.get_subscription_count()
                                        or self.pub_markers.get_subscription_count()):
            slip = slip_fields(result.slip, stamp, f)
            if self.pub_slip.get_subscription_count():
                self.pub_slip.publish(slip_msg(slip))
            if self.pub_markers.get_subscription_count():
                self.pub_markers.publish(markers_msg(slip_markers(result.slip), slip))

    def _announce_reference(self, ready: ReferenceReady) -> None:
        ref = ready.reference
        fields = pose_fields(ref.pose, ready.tag, ready.frame_id)
        self.pub_pose.publish(pose_msg(fields))
        if self.tf is not None:
            t = TransformStamped()
            apply_header(t, fields)
            t.child_frame_id = self.frame_id
            p, o = fields["pose"]["position"], fields["pose"]["orientation"]
            t.transform.translation = _vec(Vector3, p)
            t.transform.rotation.x, t.transform.rotation.y = o["x"], o["y"]
            t.transform.rotation.z, t.transform.rotation.w = o["z"], o["w"]
            self.tf.sendTransform(t)
        warning = residual_warning(ref.pose.residual_rms)
        head = f"touch: reference of {len(ref.cells)} cells from {ref.frames} frame(s); "
        if warning is not None:     # loudly: every later force is off (diagnostics: WARN)
            self.node.get_logger().warning(head + warning)
        else:
            self.node.get_logger().info(
                head + f"pad frame fit residual {ref.pose.residual_rms * 1e6:.1f} um RMS "
                f"({ref.pose.residual_max * 1e6:.1f} um max)")
