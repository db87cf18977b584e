"""The stereo_camera and sim_camera nodes, run as executables over loopback DDS."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image, PointCloud2

from tactile_sl_common.camera_info import save_camera_info_yaml
from tactile_sl_common.clouds import cloud_to_arrays
from tactile_sl_sim.optics import SimulatedCameraPair

from ros_harness import Probe, running_node

pytestmark = pytest.mark.ros


def _run(executable: str, params: dict[str, str], domain_id: int, log):
    """The camera (or simulator) node in /tactile with ``params``, its output in ``log``."""
    args = ["-r", "__ns:=/tactile"]
    for k, v in params.items():
        args += ["-p", f"{k}:={v}"]
    package = "tactile_sl_sim" if executable == "sim_camera" else "tactile_sl_camera"
    return running_node(package, executable, domain_id, args, log)


class Listener(Probe):
    """Subscribes to the camera topics in /tactile and keeps (stamp, message) per topic."""

    def __init__(self, domain_id: int, with_truth: bool = False):
        super().__init__("camera_test_listener", domain_id, namespace="/tactile")
        self.got: dict[str, list] = {}
        topics = [("left/image_raw", Image), ("right/image_raw", Image),
                  ("left/camera_info", CameraInfo), ("right/camera_info", CameraInfo)]
        if with_truth:
            topics.append(("ground_truth/points", PointCloud2))
        for topic, kind in topics:
            self.got[topic] = []
            self.node.create_subscription(
                kind, topic, lambda m, t=topic: self.got[t].append(
                    ((m.header.stamp.sec, m.header.stamp.nanosec), m)),
                qos_profile_sensor_data if kind is not PointCloud2 else 10)


def _write_video(path, values, size=(160, 120)):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 10, size)
    for v in values:
        frame = np.zeros((size[1], size[0], 3), np.uint8)
        frame[:, :] = v
        writer.write(frame)
    writer.release()


def test_stereo_camera_node_from_video_files(tmp_path, domain_id):
    left, right = tmp_path / "left.avi", tmp_path / "right.avi"
    _write_video(left, [40] * 50)
    rig = SimulatedCameraPair()
    save_camera_info_yaml(tmp_path / "left.yaml", rig.left_info)
    save_camera_info_yaml(tmp_path / "right.yaml", rig.right_info)
    log = tmp_path / "node.log"
    with _run("stereo_camera", {
        "left_device": str(left), "right_device": str(right), "width": "160", "height": "120",
        "fps": "20.0", "reopen_interval": "0.3",
        "left_camera_info_url": f"file://{tmp_path / 'left.yaml'}",
        "right_camera_info_url": str(tmp_path / "right.yaml")}, domain_id, log) as camera, \
            Listener(domain_id) as listener:
        proc = camera.process
        # the right device is missing: logged, retried, no crash
        assert listener.spin_until(lambda: "cannot be opened" in log.read_text(), 20), \
            log.read_text()
        assert proc.poll() is None
        _write_video(right, [200] * 50)
        assert listener.spin_until(lambda: len(listener.got["right/camera_info"]) >= 5, 20), \
            log.read_text()
        lstamps = {s: m for s, m in listener.got["left/image_raw"]}
        rstamps = {s: m for s, m in listener.got["right/image_raw"]}
        common = set(lstamps) & set(rstamps)
        assert len(common) >= 3  # both images of a frame carry the same stamp
        s = sorted(common)[0]
        lm, rm = lstamps[s], rstamps[s]
        assert lm.encoding == "mono8" and (lm.width, lm.height) == (160, 120)
        assert abs(np.frombuffer(bytes(lm.data), np.uint8).mean() - 40) < 3
        assert abs(np.frombuffer(bytes(rm.data), np.uint8).mean() - 200) < 3
        assert lm.header.frame_id == "tactile_left_optical_frame"
        infos = {st: m for st, m in listener.got["right/camera_info"]}
        assert set(infos) & common
        info = infos[sorted(set(infos) & common)[0]]
        assert info.p[3] == pytest.approx(rig.right_info.P[0, 3])
        assert "opened again" in log.read_text()


def test_sim_camera_node_publishes_frames_with_truth(tmp_path, domain_id):
    log = tmp_path / "sim.log"
    with _run("sim_camera", {"rate": "10.0"}, domain_id, log), \
            Listener(domain_id, with_truth=True) as listener:
        ok = listener.spin_until(lambda: len(listener.got["ground_truth/points"]) >= 2, 60)
        assert ok, log.read_text()
        truth_stamp, cloud = listener.got["ground_truth/points"][0]
        assert listener.spin_until(
            lambda: truth_stamp in {s for s, _ in listener.got["right/image_raw"]}
            and truth_stamp in {s for s, _ in listener.got["left/camera_info"]}, 5)
        points = cloud_to_arrays(cloud)
        assert len(points) > 500 and cloud.header.frame_id == "tactile_left_optical_frame"
        assert 0.013 < float(np.median(points["z"])) < 0.017
