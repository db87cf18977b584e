"""
``replay``: play a bag's Image and CameraInfo topics as a camera would publish them.

Messages are published as the recorded CDR bytes (no decode/re-encode), under relative
topic names (``/tactile/left/image_raw`` in the bag -> ``left/image_raw``), so the node is
namespaced and remapped like any camera driver. See config/replay.yaml for the parameters.
"""
from __future__ import annotations

import importlib
import threading
import time
from typing import Any

import rclpy
from rclpy.node import Node
from rclpy.serialization import deserialize_message, serialize_message

from tactile_sl_camera.replay import HEADER_FIRST_TYPES, ReplayPlan, Restamper
from tactile_sl_common.bag_io import BagError, stamp_to_ns
from tactile_sl_common.nodes import stop
from tactile_sl_common.nodes.parameters import LiveParameters, declare_qos
from tactile_sl_common.nodes.runner import run_node
from tactile_sl_common.settings import FRAME_PREFIX_DOC, frame_prefix_check


def message_class(schema_name: str) -> Any:
    """``sensor_msgs/msg/Image`` -> the rclpy message class."""
    package, kind, name = schema_name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def prefix_frame_id(cdr: bytes, schema_name: str, prefix: str) -> bytes:
    """The message with ``prefix`` prepended to its ``header.frame_id`` (CDR in and out)."""
    cls = message_class(schema_name)
    msg = deserialize_message(cdr, cls)
    msg.header.frame_id = prefix + msg.header.frame_id
    return serialize_message(msg)


def _type_check(name: str) -> str | None:
    try:
        message_class(name)
    except (ValueError, ImportError, AttributeError):
        return "not a message type (package/msg/Name) importable here"
    return None


class ReplayNode(Node):
    """Publishes a bag's camera topics at the recorded rate, a multiple of it, or paced."""

    def __init__(self) -> None:
        super().__init__("replay")
        live = LiveParameters(self)
        ro: dict[str, Any] = {"read_only": True}
        bag = str(live.declare("bag", "",
            "Path of the MCAP bag (file, or rosbag2 directory holding one .mcap).", **ro))
        topics = [t for t in live.declare("topics", [""],
            "Bag topics to play (absolute, or relative to bag_namespace). "
            "Empty: every sensor_msgs/Image and CameraInfo topic.", **ro) if t]
        bag_namespace = str(live.declare("bag_namespace", "/tactile",
            "Prefix stripped from bag topic names to form the relative published names.", **ro))
        rate = float(live.declare("rate", 1.0,
            "Playback speed: 1.0 = recorded rate, 2.0 = twice as fast, 0 = as fast as "
            "possible (combine with wait_for_topic to go as fast as a subscriber keeps up).",
            (0.0, 1000.0), **ro))
        self.loop = bool(live.declare("loop", False,
            "Start over at the end of the bag (implies restamp).", **ro))
        self.loops = int(live.declare("loops", 0,
            "With loop: number of passes over the bag, then stop (0 = forever); a change "
            "counts the passes already played.", (0, 1_000_000_000),
            apply=lambda v: setattr(self, "loops", int(v))))
        self.restamp = bool(live.declare("restamp", False,
            "Stamp each stereo frame with the time it is published (all messages of a frame "
            "get the same new stamp), as a live camera would. Always on with loop.", **ro))
        reliability = str(live.declare("reliability", "best_effort",
            "QoS reliability of the publishers: best_effort (sensor data) or reliable.",
            check=lambda v: None if v in ("best_effort", "reliable") else
            "must be best_effort or reliable", **ro))
        depth = int(live.declare("depth", 5, "QoS history depth of the publishers.",
                                 (1, 10000), **ro))
        self.min_subscribers = int(live.declare("wait_for_subscribers", 0,
            "Before playing, wait until every played topic has at least this many "
            "subscribers.", (0, 1000), **ro))
        self.subscribers_timeout = float(live.declare("wait_for_subscribers_timeout", 10.0,
            "Seconds to wait for subscribers before playing anyway.", (0.0, 3600.0), **ro))
        self.subscribers_settle = float(live.declare("wait_for_subscribers_settle", 0.5,
            "Seconds to wait after the subscribers are there, before the first message: the "
            "count is this node's side of each match, and a subscriber that has not yet "
            "matched this publisher on its side drops what arrives (best effort).",
            (0.0, 60.0), **ro))
        pace_topic = str(live.declare("wait_for_topic", "",
            "Pacing: after each stereo frame, wait for a message on this topic carrying the "
            "frame's header stamp (e.g. 'points'), so playback never outruns the consumer.",
            **ro))
        pace_type = str(live.declare("wait_for_type", "sensor_msgs/msg/PointCloud2",
            "Message type of wait_for_topic (its first field must be a std_msgs/Header).",
            check=_type_check, **ro))
        self.wait_timeout = float(live.declare("wait_timeout", 1.0,
            "Seconds to wait for the pacing message before moving on (logged).",
            (0.001, 3600.0), apply=lambda v: setattr(self, "wait_timeout", float(v))))
        self.frame_prefix = str(live.declare("frame_prefix", "", FRAME_PREFIX_DOC +
            " Applied to the recorded frame_id of every played message.",
            check=frame_prefix_check, **ro))
        self.exit_on_end = bool(live.declare("exit_on_end", True,
            "Shut the node down when the bag has been played (and loop is false).",
            apply=lambda v: setattr(self, "exit_on_end", bool(v))))

        if not bag:
            raise BagError("parameter 'bag' is empty: give the path of an MCAP bag")
        self.plan = ReplayPlan(bag, topics, bag_namespace, rate)
        if self.loop and not self.restamp:
            # A second pass would repeat the recorded stamps: consumers (the decoder's stereo
            # sync, TF, rosbag2) see time go backwards and drop the frames as stale.
            self.restamp = True
            self.get_logger().info("loop implies restamp: every pass is stamped with the time "
                                   "it is published, so stamps keep moving forward")
        qos = declare_qos(live, "output", "the played topics (reliability and depth: the "
                          "parameters of those names)", depth, reliability, fixed=("reliability",
                                                                                  "depth"))
        self.publishers_by_topic = {
            name: self.create_publisher(message_class(self.plan.types[bag_topic]), name, qos)
            for bag_topic, name in self.plan.outputs.items()}

        self._acked: set[int] = set()
        self._ack = threading.Condition()
        self.pacing = bool(pace_topic)
        if self.pacing:
            self.create_subscription(message_class(pace_type), pace_topic, self._on_pace,
                                     declare_qos(live, "pace", "the wait_for_topic "
                                                 "subscription", 10))
        self.done = threading.Event()
        self.failure: BagError | None = None    # why playing stopped early (exit status 1)
        self._done_at: float | None = None
        self._stopping = threading.Event()
        self.published = 0
        self.get_logger().info(
            f"replaying {self.plan.reader.path} ({self.plan.message_count} messages on "
            f"{', '.join(self.plan.outputs.values())}) at rate "
            f"{'max' if self.plan.rate == 0 else self.plan.rate}"
            f"{', looping' if self.loop else ''}{', restamped' if self.restamp else ''}")
        self._worker = threading.Thread(target=self._play, daemon=True)
        self._worker.start()

    def _running(self) -> bool:
        return rclpy.ok() and not self._stopping.is_set() and not stop.requested()

    def finished(self) -> bool:
        """The bag has been played (exit_on_end), and 0.3 s passed for the last delivery.

        Raises the BagError that stopped the playing thread (a chunk failing its CRC, a
        message that cannot be read), so that the node ends with one FATAL line and exit
        status 1 instead of looking like a bag played to its end.
        """
        if self.failure is not None:
            raise self.failure
        if not (self.exit_on_end and self.done.is_set()):
            return False
        if self._done_at is None:
            self._done_at = time.monotonic()
        return time.monotonic() - self._done_at >= 0.3

    def destroy_node(self) -> None:
        """Stop and join the playing thread before the publishers go."""
        self._stopping.set()
        with self._ack:
            self._ack.notify_all()
        self._worker.join(timeout=5.0)
        super().destroy_node()

    def _on_pace(self, msg: Any) -> None:
        with self._ack:
            self._acked.add(stamp_to_ns(msg.header.stamp.sec, msg.header.stamp.nanosec))
            self._ack.notify_all()

    def _wait_for_subscribers(self) -> None:
        deadline = time.monotonic() + self.subscribers_timeout
        while self._running() and time.monotonic() < deadline:
            if all(pub.get_subscription_count() >= self.min_subscribers
                   for pub in self.publishers_by_topic.values()):
                self._stopping.wait(self.subscribers_settle)
                return
            self._stopping.wait(0.02)
        if not self._running():
            return
        lacking = [name for name, pub in self.publishers_by_topic.items()
                   if pub.get_subscription_count() < self.min_subscribers]
        self.get_logger().warning(
            f"fewer than {self.min_subscribers} subscriber(s) on {', '.join(lacking)} after "
            f"{self.subscribers_timeout:.1f} s; playing anyway")

    def _wait_for_ack(self, stamp_ns: int) -> None:
        with self._ack:
            if not self._ack.wait_for(lambda: stamp_ns in self._acked or not self._running(),
                                      self.wait_timeout):
                self.get_logger().warning(
                    f"no message on the pacing topic for stamp {stamp_ns} ns within "
                    f"{self.wait_timeout:.2f} s; moving on", throttle_duration_sec=5.0)
            self._acked.discard(stamp_ns)

    def _play(self) -> None:
        try:
            if self.min_subscribers > 0:
                self._wait_for_subscribers()
            loop_index = 0
            start = time.monotonic()
            while self._running():
                last = self._play_pass(loop_index, start)
                loop_index += 1
                if not self.loop or (self.loops > 0 and loop_index >= self.loops):
                    break
                # one frame period after the last frame, as the recording would go on
                start = self.plan.next_pass_start(start, last)
            self.get_logger().info(f"finished: {self.published} messages published")
        except BagError as exc:
            self.failure = exc         # raised by finished(): FATAL, exit status 1
        finally:
            self.done.set()

    def _play_pass(self, loop_index: int, start: float) -> float:
        """Publish one pass, scheduled from ``start`` (monotonic s); when its last went out."""
        last = time.monotonic()
        restamper = Restamper(lambda: self.get_clock().now().nanoseconds) if self.restamp else None
        recorded: int | None = None     # recorded stamp of the frame being published
        published: int | None = None    # stamp it went out with
        for item in self.plan.items(loop_index):
            if self.pacing and recorded is not None and item.stamp_ns != recorded:
                assert published is not None    # set together with recorded
                self._wait_for_ack(published)
            delay = start + item.due_s - time.monotonic()
            if delay > 0:
                self._stopping.wait(delay)
            if not self._running():
                return last
            data, stamp = restamper(item) if restamper else (item.data, item.stamp_ns)
            if self.frame_prefix and item.schema_name in HEADER_FIRST_TYPES:
                data = prefix_frame_id(data, item.schema_name, self.frame_prefix)
            self.publishers_by_topic[item.topic].publish(data)
            last = time.monotonic()
            self.published += 1
            recorded, published = item.stamp_ns, stamp
        if self.pacing and published is not None:
            self._wait_for_ack(published)
        return last


def main(args: list[str] | None = None) -> None:
    """Entry point of the ``replay`` executable."""
    run_node(ReplayNode, "replay", (BagError, ValueError), args,
             finished=lambda node: node.finished())


if __name__ == "__main__":
    main()
