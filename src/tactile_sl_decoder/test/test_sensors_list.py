"""The several-sensors list (config/sensors.yaml) that sensors.launch.py starts (no ROS)."""
from __future__ import annotations

import pathlib
import py_compile

import pytest

from tactile_sl_decoder.nodes.sensors import SensorsFileError, load_sensors, parse_sensors

PKG = pathlib.Path(__file__).resolve().parents[1]


def test_shipped_list_gives_two_sensors_with_distinct_frames_and_stable_devices():
    sensors = load_sensors(PKG / "config" / "sensors.yaml")
    assert [s.namespace for s in sensors] == ["left_hand", "right_hand"]
    assert [s.frame_prefix for s in sensors] == ["left_hand_", "right_hand_"]
    for s in sensors:
        assert s.camera["frame_prefix"] == s.decoder["frame_prefix"] == s.frame_prefix
        assert s.camera["left_device"].startswith("/dev/v4l/by-id/")
        assert s.camera["right_camera_info_url"].startswith("file://")
    launch = PKG / "launch" / "sensors.launch.py"
    py_compile.compile(str(launch), doraise=True)
    assert "load_sensors" in launch.read_text()


def _one(**entry):
    base = {"namespace": "a", "left_device": "/dev/v4l/by-id/l", "right_device": "/dev/v4l/by-id/r"}
    base.update(entry)
    return base


def _workers(sensors):
    """Each decoder's camera_processes and threads overrides (None: not set)."""
    return [(s.decoder.get("camera_processes"), s.decoder.get("threads")) for s in sensors]


def test_decoders_run_in_process_on_one_thread_where_cores_are_fewer_than_two_per_sensor():
    two = {"sensors": [_one(), _one(namespace="b", left_device="/dev/v4l/by-id/l2",
                                    right_device="/dev/v4l/by-id/r2")]}
    assert _workers(parse_sensors(two, cpus=2)) == [(False, 1), (False, 1)]
    assert _workers(parse_sensors(two, cpus=4)) == [(None, None), (None, None)]
    assert _workers(parse_sensors(two, cpus=None)) == [(None, None), (None, None)]
    assert _workers(parse_sensors({"sensors": [_one()]}, cpus=2)) == [(None, None)]
    two["sensors"][0]["decoder"] = {"threads": 2}          # the entry's own settings win
    two["sensors"][1]["decoder"] = {"camera_processes": True}
    assert _workers(parse_sensors(two, cpus=2)) == [(False, 2), (True, 1)]


def test_overrides_and_side_by_side():
    (s,) = parse_sensors({"sensors": [_one(frame_prefix="x_", mirrored=True,
                                           camera={"fps": 15.0}, decoder={"min_votes": 3})]},
                         cpus=None)
    assert s.camera["fps"] == 15.0 and s.decoder == {"mirrored": True, "min_votes": 3,
                                                     "frame_prefix": "x_"}
    (s,) = parse_sensors({"sensors": [{"namespace": "b", "left_device": "/dev/v4l/by-id/sbs",
                                       "side_by_side": True}]})
    assert "right_device" not in s.camera


@pytest.mark.parametrize("doc, words", [
    ({}, "non-empty list"),
    ({"sensors": [_one(namespace="1bad")]}, "not a ROS name"),
    ({"sensors": [_one(), _one(left_device="/dev/v4l/by-id/x", right_device="/dev/y")]},
     "namespace used by more than one"),
    ({"sensors": [_one(), _one(namespace="b")]}, "device used twice"),
    ({"sensors": [_one(right_device="")]}, "right_device is required"),
    ({"sensors": [_one(frame_prefix="/x")]}, "leading '/'"),
    ({"sensors": [_one(devices="x")]}, "unknown keys"),
])
def test_bad_lists_are_refused_with_the_reason(doc, words):
    with pytest.raises(SensorsFileError, match=words):
        parse_sensors(doc)
