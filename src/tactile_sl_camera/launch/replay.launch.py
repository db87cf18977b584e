"""Replay a bag's stereo images and camera_info under /tactile.

ros2 launch tactile_sl_camera replay.launch.py bag:=bags/no_contact.mcap
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    params = os.path.join(get_package_share_directory("tactile_sl_camera"), "config", "replay.yaml")
    return LaunchDescription([
        DeclareLaunchArgument("bag", description="MCAP bag to replay"),
        DeclareLaunchArgument("namespace", default_value="tactile",
                              description="namespace of the node and its topics"),
        DeclareLaunchArgument("rate", default_value="1.0",
                              description="playback speed (1 = recorded, 0 = as fast as possible)"),
        DeclareLaunchArgument("loop", default_value="false",
                              description="start over at the end (implies restamp)"),
        DeclareLaunchArgument("restamp", default_value="false",
                              description="stamp frames with their publication time"),
        Node(
            package="tactile_sl_camera",
            executable="replay",
            namespace=LaunchConfiguration("namespace"),
            parameters=[params, {
                "bag": LaunchConfiguration("bag"),
                "rate": LaunchConfiguration("rate"),
                "loop": LaunchConfiguration("loop"),
                "restamp": LaunchConfiguration("restamp"),
            }],
            output="screen",
        ),
    ])
