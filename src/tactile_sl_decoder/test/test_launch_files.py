"""Launch files (issue 12, finding 6), only syntax-checked: launch_ros is not installed.

Every argument has a description; the sensor launch passes ``restamp`` to replay (a looping
replay needs it, see tests/test_replay_loop.py) and reads ``stages`` as a ROS boolean.
"""
from __future__ import annotations

import ast

import pytest

from ros_harness import REPO

LAUNCH_FILES = sorted(REPO.glob("src/*/launch/*.launch.py"))


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_every_launch_argument_has_a_description(path):
    tree = ast.parse(path.read_text())
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)
             and getattr(n.func, "id", "") == "DeclareLaunchArgument"]
    assert calls
    for call in calls:
        assert any(k.arg == "description" for k in call.keywords), \
            f"{path.name}:{call.lineno}: DeclareLaunchArgument without a description"


def test_sensor_launch_passes_restamp_and_reads_stages_as_a_boolean():
    text = (REPO / "src/tactile_sl_decoder/launch/tactile_sl.launch.py").read_text()
    assert '"restamp": LaunchConfiguration("restamp")' in text
    assert "== 'true'" not in text and ".lower() in ('true', '1')" in text


def test_stage_launch_passes_max_rate_as_a_double():
    """ros2 launch would pass max_rate:=20 as an integer, which a double parameter refuses."""
    symbols = (REPO / "src/tactile_sl_decoder/launch/symbols.launch.py").read_text()
    assert 'ParameterValue(LaunchConfiguration("max_rate"), value_type=float)' in symbols
    assert '{"max_rate": max_rate}' in symbols
    sensor = (REPO / "src/tactile_sl_decoder/launch/tactile_sl.launch.py").read_text()
    assert '"max_rate": LaunchConfiguration("stage_max_rate")' in sensor
