"""Several sensors on one robot, from one YAML list: a stereo_camera and a decoder each.

ros2 launch tactile_sl_decoder sensors.launch.py sensors_file:=/etc/tactile_sl/sensors.yaml

Every entry of the list (see config/sensors.yaml and
:mod:`tactile_sl_decoder.nodes.sensors`) gives a namespace, the two camera devices (stable
/dev/v4l/by-id/... paths), the calibration files and optional overrides; frame ids get the
sensor's frame_prefix (default '<namespace>_') so the sensors' frames are distinct.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from tactile_sl_decoder.nodes.sensors import load_sensors


def _nodes(context, *args, **kwargs):
    """One stereo_camera and one decoder per sensor of sensors_file."""
    decoder_share = get_package_share_directory("tactile_sl_decoder")
    camera_share = get_package_share_directory("tactile_sl_camera")
    camera_yaml = os.path.join(camera_share, "config", "stereo_camera.yaml")
    decoder_yaml = os.path.join(decoder_share, "config", "decoder.yaml")
    sensors = load_sensors(LaunchConfiguration("sensors_file").perform(context))
    nodes = []
    for sensor in sensors:
        nodes.append(Node(
            package="tactile_sl_camera", executable="stereo_camera", name="stereo_camera",
            namespace=sensor.namespace, parameters=[camera_yaml, sensor.camera],
            output="screen"))
        nodes.append(Node(
            package="tactile_sl_decoder", executable="decoder", name="decoder",
            namespace=sensor.namespace, parameters=[decoder_yaml, sensor.decoder],
            output="screen"))
    return nodes


def generate_launch_description() -> LaunchDescription:
    """The sensors_file argument and the nodes of every sensor in it."""
    default = os.path.join(get_package_share_directory("tactile_sl_decoder"), "config",
                           "sensors.yaml")
    return LaunchDescription([
        DeclareLaunchArgument("sensors_file", default_value=default,
                              description="YAML list of sensors (namespace, devices, "
                              "calibration files, frame_prefix); see config/sensors.yaml"),
        OpaqueFunction(function=_nodes),
    ])
