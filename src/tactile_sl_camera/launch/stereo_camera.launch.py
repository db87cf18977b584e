"""Launch the real stereo camera in /tactile with its parameter file.

ros2 launch tactile_sl_camera stereo_camera.launch.py \
    left_camera_info_url:=file:///path/left.yaml right_camera_info_url:=file:///path/right.yaml
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description():
    share = get_package_share_directory("tactile_sl_camera")
    args = {
        "namespace": "/tactile",
        "params_file": os.path.join(share, "config", "stereo_camera.yaml"),
        "left_device": "0",
        "right_device": "1",
        "left_camera_info_url": "",
        "right_camera_info_url": "",
    }
    descriptions = {
        "namespace": "namespace of the node and its topics",
        "params_file": "parameters YAML (default: the package's config/stereo_camera.yaml)",
        "left_device": "left camera: index, /dev/v4l/by-id/... path or video file",
        "right_device": "right camera: index, /dev/v4l/by-id/... path or video file",
        "left_camera_info_url": "camera_calibration YAML of the left camera",
        "right_camera_info_url": "camera_calibration YAML of the right camera",
    }
    declared = [DeclareLaunchArgument(k, default_value=v, description=descriptions[k])
                for k, v in args.items()]
    strings = ("left_device", "right_device", "left_camera_info_url", "right_camera_info_url")
    node = Node(
        package="tactile_sl_camera", executable="stereo_camera", name="stereo_camera",
        namespace=LaunchConfiguration("namespace"), output="screen",
        parameters=[LaunchConfiguration("params_file"), {  # strings stay strings ("0")
            name: ParameterValue(LaunchConfiguration(name), value_type=str) for name in strings
        }])
    return LaunchDescription([*declared, node])
