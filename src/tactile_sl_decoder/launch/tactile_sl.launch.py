"""The whole sensor: a source of stereo images (bag replay or camera) and the decoder.

ros2 launch tactile_sl_decoder tactile_sl.launch.py bag:=bags/press.mcap
ros2 launch tactile_sl_decoder tactile_sl.launch.py bag:=bags/press.mcap stages:=true
ros2 launch tactile_sl_decoder tactile_sl.launch.py source:=camera
ros2 launch tactile_sl_decoder tactile_sl.launch.py bag:=bags/press.mcap loop:=true rviz:=true

source:=replay (default) plays `bag` with tactile_sl_camera's replay node; source:=camera
starts tactile_sl_camera's stereo_camera node instead.  stages:=false (default) runs
extraction and classification inside the decoder (lowest latency); stages:=true chains the
symbol_extractor / symbol_classifier nodes per camera and the decoder consumes their
labelled SymbolArrays, giving the same points.  rviz:=true opens RViz with
share/tactile_sl_decoder/rviz/tactile_sl.rviz (points, field, wrench, pad_pose, depth; its
topics are under /tactile).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription
from launch.conditions import IfCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import EqualsSubstitution, LaunchConfiguration, PythonExpression
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    """Source node, optional stage nodes, decoder; all in one namespace."""
    decoder_share = get_package_share_directory("tactile_sl_decoder")
    camera_share = get_package_share_directory("tactile_sl_camera")
    ns = LaunchConfiguration("namespace")
    stages = LaunchConfiguration("stages")
    decoder_yaml = os.path.join(decoder_share, "config", "decoder.yaml")
    replay_yaml = os.path.join(camera_share, "config", "replay.yaml")
    camera_yaml = os.path.join(camera_share, "config", "stereo_camera.yaml")
    rviz_config = os.path.join(decoder_share, "rviz", "tactile_sl.rviz")
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="/tactile",
                              description="namespace of every node and topic"),
        DeclareLaunchArgument("source", default_value="replay",
                              description="replay (a bag) or camera"),
        DeclareLaunchArgument("bag", default_value="", description="bag for source:=replay"),
        DeclareLaunchArgument("rate", default_value="1.0", description="replay speed"),
        DeclareLaunchArgument("loop", default_value="false",
                              description="replay: start over at the end (implies restamp)"),
        DeclareLaunchArgument("restamp", default_value="false",
                              description="replay: stamp frames with their publication time"),
        DeclareLaunchArgument("stages", default_value="false",
                              description="true/false (any ROS boolean spelling): chain the "
                              "extraction/classification stage nodes"),
        DeclareLaunchArgument("stage_max_rate", default_value="0.0",
                              description="stages:=true: frames per second the stage chain "
                              "takes at most, the same frames from both cameras (0: all)"),
        DeclareLaunchArgument("mirrored", default_value="false",
                              description="the cameras see the artwork mirrored"),
        DeclareLaunchArgument("rviz", default_value="false",
                              description="true: open RViz with rviz/tactile_sl.rviz (cloud, "
                              "touch field, wrench, pad pose, depth image)"),
        Node(package="rviz2", executable="rviz2", name="rviz2",
             arguments=["-d", rviz_config], condition=IfCondition(LaunchConfiguration("rviz")),
             output="screen"),
        Node(
            package="tactile_sl_camera", executable="replay", name="replay", namespace=ns,
            parameters=[replay_yaml, {"bag": LaunchConfiguration("bag"),
                                      "rate": LaunchConfiguration("rate"),
                                      "loop": LaunchConfiguration("loop"),
                                      "restamp": LaunchConfiguration("restamp")}],
            condition=IfCondition(EqualsSubstitution(LaunchConfiguration("source"), "replay")),
            output="screen"),
        Node(
            package="tactile_sl_camera", executable="stereo_camera", name="stereo_camera",
            namespace=ns, parameters=[camera_yaml],
            condition=IfCondition(EqualsSubstitution(LaunchConfiguration("source"), "camera")),
            output="screen"),
        IncludeLaunchDescription(
            PythonLaunchDescriptionSource(
                os.path.join(decoder_share, "launch", "symbols.launch.py")),
            launch_arguments={"namespace": ns,
                              "max_rate": LaunchConfiguration("stage_max_rate")}.items(),
            condition=IfCondition(stages)),
        Node(
            package="tactile_sl_decoder", executable="decoder", name="decoder", namespace=ns,
            parameters=[decoder_yaml, {
                "input": PythonExpression(["'symbols' if '", stages,
                                           "'.strip().lower() in ('true', '1') else 'images'"]),
                "mirrored": LaunchConfiguration("mirrored")}],
            remappings=[("left/symbols", "left/labelled_symbols"),
                        ("right/symbols", "right/labelled_symbols")],
            output="screen"),
    ])
