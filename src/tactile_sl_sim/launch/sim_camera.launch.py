"""Launch the simulated sensor in /tactile with its parameter file.

ros2 launch tactile_sl_sim sim_camera.launch.py scenes_file:=/path/scenes.yaml scene:=edge
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description():
    share = get_package_share_directory("tactile_sl_sim")
    args = {
        "namespace": "/tactile",
        "params_file": os.path.join(share, "config", "sim_camera.yaml"),
        "scenes_file": "",
        "scene": "",
    }
    descriptions = {
        "namespace": "namespace of the node and its topics",
        "params_file": "parameters YAML (default: the package's config/sim_camera.yaml)",
        "scenes_file": "scenes YAML; empty = the built-in sphere press",
        "scene": "scene name in scenes_file; empty = the first",
    }
    declared = [DeclareLaunchArgument(k, default_value=v, description=descriptions[k])
                for k, v in args.items()]
    node = Node(
        package="tactile_sl_sim", executable="sim_camera", name="sim_camera",
        namespace=LaunchConfiguration("namespace"), output="screen",
        parameters=[LaunchConfiguration("params_file"), {  # strings stay strings ("0")
            "scenes_file": ParameterValue(LaunchConfiguration("scenes_file"), value_type=str),
            "scene": ParameterValue(LaunchConfiguration("scene"), value_type=str),
        }])
    return LaunchDescription([*declared, node])
