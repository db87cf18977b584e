"""rviz/tactile_sl.rviz: installed, shows the cloud and the touch topics; the launch opens it."""
from __future__ import annotations

import pathlib
import py_compile

import yaml

PKG = pathlib.Path(__file__).resolve().parents[1]


def test_rviz_config_shows_cloud_and_touch_topics_and_is_installed():
    doc = yaml.safe_load((PKG / "rviz" / "tactile_sl.rviz").read_text())
    manager = doc["Visualization Manager"]
    displays = {d["Topic"]["Value"]: d["Class"] for d in manager["Displays"] if "Topic" in d}
    assert displays["/tactile/points"] == "rviz_default_plugins/PointCloud2"
    assert displays["/tactile/field"] == "rviz_default_plugins/PointCloud2"
    assert displays["/tactile/wrench"] == "rviz_default_plugins/Wrench"
    assert displays["/tactile/depth"] == "rviz_default_plugins/Image"
    assert displays["/tactile/pad_pose"] == "rviz_default_plugins/Pose"
    assert displays["/tactile/slip_markers"] == "rviz_default_plugins/MarkerArray"
    assert manager["Global Options"]["Fixed Frame"] == "tactile_left_optical_frame"
    assert 'glob("rviz/*.rviz")' in (PKG / "setup.py").read_text()
    launch = PKG / "launch" / "tactile_sl.launch.py"
    py_compile.compile(str(launch), doraise=True)
    text = launch.read_text()
    assert 'DeclareLaunchArgument("rviz"' in text and "tactile_sl.rviz" in text
