"""Extraction and classification stages for both cameras, chained over DDS.

ros2 launch tactile_sl_decoder symbols.launch.py [namespace:=/tactile] [max_rate:=20]
  left/image_raw -> left/symbols -> left/labelled_symbols (and the same for right).
max_rate: the extractors take at most that many stereo frames per second, the same ones on
both sides (chosen by stamp); for machines too slow for the camera rate (docs/decoder.md).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description() -> LaunchDescription:
    """Four nodes: extractor and classifier per camera, parameters from config/."""
    share = get_package_share_directory("tactile_sl_decoder")
    extractor_yaml = os.path.join(share, "config", "symbol_extractor.yaml")
    classifier_yaml = os.path.join(share, "config", "symbol_classifier.yaml")
    ns = LaunchConfiguration("namespace")
    # a double whatever the spelling (max_rate:=20 would otherwise be an integer)
    max_rate = ParameterValue(LaunchConfiguration("max_rate"), value_type=float)
    nodes = []
    for side in ("left", "right"):
        nodes.append(Node(
            package="tactile_sl_decoder", executable="symbol_extractor",
            name="symbol_extractor", namespace=[ns, "/", side],
            parameters=[extractor_yaml, {"max_rate": max_rate}],
            remappings=[("image", "image_raw")], output="screen"))
        nodes.append(Node(
            package="tactile_sl_decoder", executable="symbol_classifier",
            name="symbol_classifier", namespace=[ns, "/", side],
            parameters=[classifier_yaml], output="screen"))
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="/tactile",
                              description="namespace holding left/ and right/ image topics"),
        DeclareLaunchArgument("max_rate", default_value="0.0",
                              description="stereo frames per second the extractors take at "
                              "most, chosen by stamp (0: every frame)"),
        *nodes,
    ])
