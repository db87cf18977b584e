"""Extraction and classification stages for both cameras, chained over DDS.

ros2 launch tactile_sl_decoder symbols.launch.py [namespace:=/tactile]
  left/image_raw -> left/symbols -> left/labelled_symbols (and the same for right).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    """Four nodes: extractor and classifier per camera, parameters from config/."""
    share = get_package_share_directory("tactile_sl_decoder")
    extractor_yaml = os.path.join(share, "config", "symbol_extractor.yaml")
    classifier_yaml = os.path.join(share, "config", "symbol_classifier.yaml")
    ns = LaunchConfiguration("namespace")
    nodes = []
    for side in ("left", "right"):
        nodes.append(Node(
            package="tactile_sl_decoder", executable="symbol_extractor",
            name="symbol_extractor", namespace=[ns, "/", side], parameters=[extractor_yaml],
            remappings=[("image", "image_raw")], output="screen"))
        nodes.append(Node(
            package="tactile_sl_decoder", executable="symbol_classifier",
            name="symbol_classifier", namespace=[ns, "/", side],
            parameters=[classifier_yaml], output="screen"))
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="/tactile",
                              description="namespace holding left/ and right/ image topics"),
        *nodes,
    ])
