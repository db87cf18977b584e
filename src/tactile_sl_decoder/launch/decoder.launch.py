"""The decoder alone, next to a camera publishing images and camera_info.

ros2 launch tactile_sl_decoder decoder.launch.py [namespace:=/tactile] [input:=images]
  left|right/image_raw + left|right/camera_info -> points (+ left|right/symbols_decoded)
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    """One decoder node, parameters from config/decoder.yaml plus launch overrides."""
    params = os.path.join(get_package_share_directory("tactile_sl_decoder"), "config",
                          "decoder.yaml")
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="/tactile",
                              description="namespace holding left/ and right/ topics"),
        DeclareLaunchArgument("input", default_value="images",
                              description="images (in-process stages) or symbols"),
        DeclareLaunchArgument("mirrored", default_value="false",
                              description="cameras see the artwork mirrored"),
        Node(
            package="tactile_sl_decoder", executable="decoder", name="decoder",
            namespace=LaunchConfiguration("namespace"),
            parameters=[params, {"input": LaunchConfiguration("input"),
                                 "mirrored": LaunchConfiguration("mirrored")}],
            remappings=[("left/symbols", "left/labelled_symbols"),
                        ("right/symbols", "right/labelled_symbols")],
            output="screen"),
    ])
