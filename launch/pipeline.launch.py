"""The online pipeline: sim_node (or a real vehicle's sensor topics), preprocess_node,
estimator_node and controller_node, optionally recorder_node, each with its parameter file
config/<node>.params.yaml (every parameter, its default and meaning).

    ros2 launch dampest_ros pipeline.launch.py                     # the simulated vehicle
    ros2 launch dampest_ros pipeline.launch.py sim:=false          # a real vehicle's topics
    ros2 launch dampest_ros pipeline.launch.py namespace:=/rov1 record:=true
    ros2 launch dampest_ros pipeline.launch.py controller:=true     # the model in the loop

Arguments: sim (true: start sim_node and run every node on its /clock), vehicle (the preset
or vehicle YAML of every node), namespace, controller (start controller_node; off by default:
the simulated vehicle obeys its cmd_wrench instead of the excitation protocol, so a controller
holding a zero reference stops identification), record (start
recorder_node: a bag of the sensor, sample, model and diagnostics topics in the working
directory). A value of a parameter file is changed with a copy of the file, or at runtime
with ros2 param set.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription

CONFIG = os.path.join(get_package_share_directory("dampest_ros"), "config")


def generate_launch_description() -> LaunchDescription:
    sim = LaunchConfiguration("sim")
    namespace = LaunchConfiguration("namespace")
    common = {"use_sim_time": sim, "vehicle": LaunchConfiguration("vehicle")}
    return LaunchDescription([
        DeclareLaunchArgument("sim", default_value="true",
                              description="start sim_node; every node on its /clock"),
        DeclareLaunchArgument("vehicle", default_value="bluerov2_heavy",
                              description="vehicle preset name or YAML path"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="namespace of every node and topic"),
        DeclareLaunchArgument("controller", default_value="false",
                              description="start controller_node (the vehicle then follows "
                                          "its commands, not the excitation protocol)"),
        DeclareLaunchArgument("record", default_value="false",
                              description="start recorder_node"),
        Node(package="dampest_ros", executable="sim_node", name="sim_node",
             namespace=namespace, output="screen", condition=IfCondition(sim),
             parameters=[os.path.join(CONFIG, "sim_node.params.yaml"),
                         {"vehicle": LaunchConfiguration("vehicle")}]),
        Node(package="dampest_ros", executable="preprocess_node", name="preprocess_node",
             namespace=namespace, output="screen",
             parameters=[os.path.join(CONFIG, "preprocess_node.params.yaml"), common]),
        Node(package="dampest_ros", executable="estimator_node", name="estimator_node",
             namespace=namespace, output="screen",
             parameters=[os.path.join(CONFIG, "estimator_node.params.yaml"), common]),
        Node(package="dampest_ros", executable="controller_node", name="controller_node",
             namespace=namespace, output="screen",
             condition=IfCondition(LaunchConfiguration("controller")),
             parameters=[os.path.join(CONFIG, "controller_node.params.yaml"), common]),
        Node(package="dampest_ros", executable="recorder_node", name="recorder_node",
             namespace=namespace, output="screen",
             condition=IfCondition(LaunchConfiguration("record")),
             parameters=[os.path.join(CONFIG, "recorder_node.params.yaml"),
                         {"use_sim_time": sim}]),
    ])
