"""``sim_camera``: the simulated sensor as a camera driver, with ground truth.

Renders a scene (from a scenes YAML file, or a built-in press / hold / release of a sphere)
and publishes ``left/image_raw``, ``right/image_raw``, ``left/camera_info``,
``right/camera_info`` (sensor-data QoS) and ``ground_truth/points`` with one stamp per stereo
frame, exactly what ``tactile-sl synth`` writes into bags. See config/sim_camera.yaml.
"""
from __future__ import annotations

import threading
import time
from typing import Any

import rclpy
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from tactile_sl_common.nodes.messages import camera_info_msg, cloud_msg, image_msg
from tactile_sl_common.nodes.parameters import LiveParameters, declare_qos
from tactile_sl_common.nodes.runner import run_node
from tactile_sl_common.settings import FRAME_PREFIX_DOC, frame_prefix_check
from tactile_sl_sim.artwork import ArtworkError
from tactile_sl_sim.scenes import SceneError, load_scenes, parse_scene
from tactile_sl_sim.synth import FrameIds, RendererCache, frame_messages, render_scene_frame

BUILTIN_SCENE = {
    "name": "sphere_press", "frames": 20, "fps": 10,
    "contacts": [{"indenter": {"kind": "sphere", "radius": 0.005},
                  "keyframes": [{"frame": 0, "depth": 0.0}, {"frame": 8, "depth": 0.0007},
                                {"frame": 12, "depth": 0.0007}, {"frame": 19, "depth": 0.0}]}],
}


class SimCameraNode(Node):
    """Render (once per scene frame, cached) and publish at the scene's rate, looping."""

    def __init__(self) -> None:
        super().__init__("sim_camera")
        live = LiveParameters(self)
        ro: dict[str, Any] = {"read_only": True}
        scenes_file = str(live.declare("scenes_file", "", "Scenes YAML (see docs/camera.md); "
                                       "empty = a built-in sphere press/hold/release.", **ro))
        scene_name = str(live.declare("scene", "", "Scene to play; empty = the first.", **ro))
        artwork = str(live.declare("artwork", "", "Artwork PNG with .png.yaml sidecar; empty = "
                                   "share/tactile_sl_sim/artwork/pattern.png.", **ro))
        rate = float(live.declare("rate", 0.0, "Frames per second; 0 = the scene's fps.",
                                  (0.0, 1000.0), apply=self._set_rate))
        self.loop = bool(live.declare("loop", True, "Start the scene over at its end.",
                                      apply=lambda v: setattr(self, "loop", bool(v))))
        self.publish_truth = bool(live.declare("publish_ground_truth", True,
                                               "Publish ground_truth/points.", **ro))
        self.cache = bool(live.declare("cache_frames", True, "Render each frame once and "
                                       "replay it when looping (noise then repeats).",
                                       apply=lambda v: setattr(self, "cache", bool(v))))
        encoding = str(live.declare("encoding", "", "mono8 or bgr8; empty = the scene's.",
                                    check=lambda v: None if v in ("", "mono8", "bgr8") else
                                    "must be mono8, bgr8 or empty", **ro))
        left_frame = str(live.declare("left_frame_id", "tactile_left_optical_frame",
                                      "Left frame_id (after frame_prefix).", **ro))
        right_frame = str(live.declare("right_frame_id", "tactile_right_optical_frame",
                                       "Right frame_id (after frame_prefix).", **ro))
        prefix = str(live.declare("frame_prefix", "", FRAME_PREFIX_DOC,
                                  check=frame_prefix_check, **ro))
        self.ids = FrameIds(prefix + left_frame, prefix + right_frame,
                            prefix + FrameIds().pad)
        if scenes_file:
            scenes = load_scenes(scenes_file)
            by_name = {s.name: s for s in scenes}
            if scene_name and scene_name not in by_name:
                raise SceneError(f"{scenes_file}: no scene {scene_name!r} (have: "
                                 f"{', '.join(by_name)})")
            self.scene = by_name[scene_name] if scene_name else scenes[0]
        else:
            self.scene = parse_scene(dict(BUILTIN_SCENE))
        if encoding:
            self.scene.encoding = encoding
        self.period = 1.0 / (rate if rate > 0 else self.scene.fps)
        self.renderer = RendererCache(artwork or None).get(self.scene)
        qos = declare_qos(live, "images", "the image and camera_info publishers", 5,
                          "best_effort")
        self.pubs: dict[str, Any] = {
            "left/image_raw": self.create_publisher(Image, "left/image_raw", qos),
            "right/image_raw": self.create_publisher(Image, "right/image_raw", qos),
            "left/camera_info": self.create_publisher(CameraInfo, "left/camera_info", qos),
            "right/camera_info": self.create_publisher(CameraInfo, "right/camera_info", qos),
        }
        if self.publish_truth:
            self.pubs["ground_truth/points"] = self.create_publisher(
                PointCloud2, "ground_truth/points",
                declare_qos(live, "ground_truth", "ground_truth/points", 10))
        self._frames: dict[int, list[tuple[str, str, dict[str, Any]]]] = {}
        self.published = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        self.get_logger().info(
            f"simulating scene {self.scene.name!r} ({self.scene.frames} frames, "
            f"{1 / self.period:g} fps, {self.scene.encoding}"
            f"{', looping' if self.loop else ''}) from {self.renderer.artwork.source}")

    def _set_rate(self, value: float) -> None:
        self.period = 1.0 / (value if value > 0 else self.scene.fps)

    def _messages(self, index: int) -> list[tuple[str, str, dict[str, Any]]]:
        if index in self._frames:
            return self._frames[index]
        frame = render_scene_frame(self.scene, self.renderer, index)
        msgs = frame_messages(self.scene, self.renderer, frame, 0, self.ids)
        if self.cache:
            self._frames[index] = msgs
        return msgs

    def _run(self) -> None:
        next_time = time.monotonic()
        index = 0
        while rclpy.ok() and not self._stop.is_set():
            try:
                msgs = self._messages(index)
            except Exception as exc:  # a frame that cannot be rendered is skipped, not fatal
                self.get_logger().error(f"frame {index} not rendered: {exc!r}",
                                        throttle_duration_sec=5.0)
                msgs = []
            wait = next_time - time.monotonic()
            if wait > 0 and self._stop.wait(wait):
                break
            next_time = max(next_time + self.period, time.monotonic() - self.period)
            stamp = self.get_clock().now().to_msg()  # one stamp for the whole stereo frame
            for topic, _schema, fields in msgs:
                if topic not in self.pubs:
                    continue
                if topic.endswith("image_raw"):
                    msg = image_msg(fields, stamp, fields["header"]["frame_id"])
                elif topic.endswith("camera_info"):
                    msg = camera_info_msg(fields, stamp)
                else:
                    msg = cloud_msg(fields, stamp)
                self.pubs[topic].publish(msg)
            self.published += 1
            index += 1
            if index >= self.scene.frames:
                if not self.loop:
                    self.get_logger().info("scene finished")
                    break
                index = 0

    def destroy_node(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Entry point of the ``sim_camera`` executable."""
    run_node(SimCameraNode, "sim_camera", (SceneError, ArtworkError, ValueError, OSError), args)


if __name__ == "__main__":
    main()
