"""``stereo_camera``: a real stereo camera (two devices or one side-by-side) through OpenCV.

Publishes ``left/image_raw``, ``right/image_raw`` (sensor-data QoS), ``left/camera_info`` and
``right/camera_info``, all four with one shared stamp per stereo frame. Calibration comes from
camera_calibration YAML files (``left_camera_info_url`` / ``right_camera_info_url``, e.g.
written by ``tactile-sl calibrate``). A lost device is logged and reopened; see
config/stereo_camera.yaml for every parameter.
"""
from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image

from tactile_sl_camera.stereo_capture import CaptureConfig, StereoCapture
from tactile_sl_common.camera_info import (
    CameraCalibration,
    CameraInfoError,
    camera_info_fields,
    load_camera_info_yaml,
)
from tactile_sl_common.images import image_fields
from tactile_sl_common.nodes.messages import camera_info_msg, image_msg
from tactile_sl_common.nodes.parameters import LiveParameters, declare_qos
from tactile_sl_common.nodes.runner import run_node
from tactile_sl_common.settings import FRAME_PREFIX_DOC, frame_prefix_check


class StereoCameraNode(Node):
    """Capture thread -> one stamp per pair -> images and camera_info."""

    def __init__(self) -> None:
        super().__init__("stereo_camera")
        live = LiveParameters(self)
        ro: dict[str, Any] = {"read_only": True}
        cfg = CaptureConfig(
            left_device=str(live.declare("left_device", "0", "Left camera: index (0), device "
                                         "path (/dev/v4l/by-id/...) or video file/URL.", **ro)),
            right_device=str(live.declare("right_device", "1", "Right camera (ignored when "
                                          "side_by_side).", **ro)),
            side_by_side=bool(live.declare("side_by_side", False, "One device delivering "
                                           "left|right side by side.", **ro)),
            width=int(live.declare("width", 640, "Width of one camera's image, pixels.",
                                   (1, 16384), **ro)),
            height=int(live.declare("height", 480, "Image height, pixels.", (1, 16384), **ro)),
            fps=float(live.declare("fps", 30.0, "Frame rate requested and maximum rate "
                                   "published (video files are paced to it).", (0.01, 1000.0),
                                   **ro)),
            encoding=str(live.declare("encoding", "mono8", "Output pixel format: mono8 or bgr8.",
                                      check=lambda v: None if v in ("mono8", "bgr8") else
                                      "must be mono8 or bgr8", **ro)),
            fourcc=str(live.declare("fourcc", "", "Device pixel format, e.g. MJPG; empty = "
                                    "driver default.", check=lambda v: None if len(v) in (0, 4)
                                    else "must be four characters (e.g. MJPG) or empty", **ro)),
            reopen_interval=float(live.declare(
                "reopen_interval", 1.0, "Seconds between attempts to reopen a lost device.",
                (0.01, 3600.0), apply=self._set_reopen_interval)))
        frames = (
            str(live.declare("left_frame_id", "tactile_left_optical_frame",
                             "frame_id of the left images and camera_info (after "
                             "frame_prefix).", **ro)),
            str(live.declare("right_frame_id", "tactile_right_optical_frame",
                             "frame_id of the right images and camera_info (after "
                             "frame_prefix).", **ro)))
        prefix = str(live.declare("frame_prefix", "", FRAME_PREFIX_DOC,
                                  check=frame_prefix_check, **ro))
        self.frame_ids = (prefix + frames[0], prefix + frames[1])
        urls = (str(live.declare("left_camera_info_url", "", "camera_calibration YAML of the "
                                 "left camera (file://, package:// or a path); empty = "
                                 "uncalibrated.", **ro)),
                str(live.declare("right_camera_info_url", "", "Same for the right camera.",
                                 **ro)))
        self.calibrations = [self._load_info(url, side, cfg)
                             for url, side in zip(urls, ("left", "right"))]
        self.capture = StereoCapture(cfg, log=self._log)
        self.cfg = cfg
        qos = declare_qos(live, "images", "the image and camera_info publishers", 5,
                          "best_effort")
        self.pub_images = [self.create_publisher(Image, f"{s}/image_raw", qos)
                           for s in ("left", "right")]
        self.pub_infos = [self.create_publisher(CameraInfo, f"{s}/camera_info", qos)
                          for s in ("left", "right")]
        self._size_checked = False
        self.published = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        self.get_logger().info(
            f"stereo camera: {'side-by-side ' + repr(cfg.left_device) if cfg.side_by_side else f'{cfg.left_device!r} + {cfg.right_device!r}'}"  # noqa: E501
            f", {cfg.width}x{cfg.height} {cfg.encoding} at up to {cfg.fps:g} fps")

    def _set_reopen_interval(self, value: float) -> None:
        self.cfg.reopen_interval = float(value)

    def _log(self, level: str, text: str) -> None:
        # one call site per severity: rclpy refuses a severity change at the same call site
        logger = self.get_logger()
        if level == "error":
            logger.error(text)
        elif level == "warning":
            logger.warning(text)
        else:
            logger.info(text)

    def _load_info(self, url: str, side: str, cfg: CaptureConfig) -> CameraCalibration:
        if url:
            try:
                calib = load_camera_info_yaml(url)
                self.get_logger().info(f"{side} calibration loaded from {url}")
                return calib
            except CameraInfoError as exc:
                self.get_logger().error(f"{side} calibration not loaded: {exc}; publishing an "
                                        "uncalibrated CameraInfo")
        else:
            self.get_logger().warning(f"{side}_camera_info_url is empty: publishing an "
                                      "uncalibrated CameraInfo (run tactile-sl calibrate)")
        return CameraCalibration(cfg.width, cfg.height, np.zeros((3, 3)), np.zeros(5),
                                 np.eye(3), np.zeros((3, 4)), camera_name=side)

    def _run(self) -> None:
        period = 1.0 / self.cfg.fps
        last = 0.0
        while rclpy.ok() and not self._stop.is_set():
            try:
                grab = self.capture.read()
                if grab is None:
                    self._stop.wait(0.05)
                    continue
                stamp = self.get_clock().now().to_msg()  # one stamp for the whole stereo frame
                self.publish(grab.left, grab.right, stamp)
            except Exception as exc:  # keep capturing whatever one frame did
                self.get_logger().error(f"capture failed: {exc!r}", throttle_duration_sec=5.0)
                self._stop.wait(0.1)
            wait = last + period - time.monotonic()
            if wait > 0:
                self._stop.wait(wait)
            last = time.monotonic()

    def publish(self, left: np.ndarray, right: np.ndarray, stamp: object) -> None:
        if not self._size_checked:
            for calib, side in zip(self.calibrations, ("left", "right")):
                if calib.is_calibrated and (calib.width, calib.height) != (left.shape[1],
                                                                           left.shape[0]):
                    self.get_logger().warning(
                        f"{side} calibration is for {calib.width}x{calib.height} but images "
                        f"are {left.shape[1]}x{left.shape[0]}")
            self._size_checked = True
        for i, image in enumerate((left, right)):
            self.pub_images[i].publish(image_msg(image_fields(image, self.cfg.encoding), stamp,
                                                 self.frame_ids[i]))
            info = camera_info_fields(self.calibrations[i], (0, 0), self.frame_ids[i])
            info["height"], info["width"] = image.shape[0], image.shape[1]
            self.pub_infos[i].publish(camera_info_msg(info, stamp))
        self.published += 1

    def destroy_node(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.capture.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Entry point of the ``stereo_camera`` executable."""
    run_node(StereoCameraNode, "stereo_camera", (ValueError, OSError), args)


if __name__ == "__main__":
    main()
