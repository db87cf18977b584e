"""The browser view of one sensor's decoder outputs.

ros2 launch tactile_sl_viewer viewer.launch.py            # http://127.0.0.1:8080/
ros2 launch tactile_sl_viewer viewer.launch.py host:=0.0.0.0 port:=8081
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description():
    params = os.path.join(get_package_share_directory("tactile_sl_viewer"), "config",
                          "viewer.yaml")
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="tactile",
                              description="namespace of the sensor whose outputs are shown"),
        DeclareLaunchArgument("host", default_value="127.0.0.1",
                              description="address to serve on (0.0.0.0: every interface)"),
        DeclareLaunchArgument("port", default_value="8080",
                              description="TCP port of the page"),
        Node(
            package="tactile_sl_viewer",
            executable="viewer",
            namespace=LaunchConfiguration("namespace"),
            parameters=[params, {
                "host": LaunchConfiguration("host"),
                "port": ParameterValue(LaunchConfiguration("port"), value_type=int),
            }],
            output="screen",
        ),
    ])
