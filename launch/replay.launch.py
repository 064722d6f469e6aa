"""A recorded bag through the pipeline: replay_node plays it with its timing and publishes
/clock with the bag time; preprocess_node and estimator_node run on that clock. Each node
reads its parameter file config/<node>.params.yaml.

    ros2 launch dampest_ros replay.launch.py bag:=bags/sample
    ros2 launch dampest_ros replay.launch.py bag:=bags/pool_run rate:=5.0 vehicle:=my_rov.yaml

Arguments: bag (required: rosbag2 directory or .mcap/.db3 file), rate (bag seconds per
wall-clock second), vehicle (the preset or vehicle YAML of the pipeline), topics (the bag
topics played; by default the sensor topics only, so that a bag recorded with `dampest record`
does not replay its dampest/* outputs into the running preprocess and estimator nodes; add
wrench for a vehicle that logs its body wrench). The topics are played under their recorded
names (the replay_node parameter remap renames them). delay (seconds, 1 by default) is waited
after replay_node's publishers have matched the nodes' subscriptions and before it plays: the
sensor topics are best effort, and a subscriber's side of the match can come later than the
publisher's (the first 0.3 s of playback were lost so in one of five runs without it).

    ros2 launch dampest_ros replay.launch.py bag:=my_bag topics:="[imu/data, dvl/twist, wrench]"
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription

CONFIG = os.path.join(get_package_share_directory("dampest_ros"), "config")
#: What the pipeline's preprocess_node reads (docs/architecture.md §3), not its outputs.
SENSOR_TOPICS = "[imu/data, dvl/twist, pressure, thrusters/state]"


def generate_launch_description() -> LaunchDescription:
    common = {"use_sim_time": True, "vehicle": LaunchConfiguration("vehicle")}
    return LaunchDescription([
        DeclareLaunchArgument("bag", description="rosbag2 directory or .mcap/.db3 file"),
        DeclareLaunchArgument("rate", default_value="1.0",
                              description="bag seconds per wall-clock second"),
        DeclareLaunchArgument("vehicle", default_value="bluerov2_heavy",
                              description="vehicle preset name or YAML path"),
        DeclareLaunchArgument("topics", default_value=SENSOR_TOPICS,
                              description="bag topics to play (YAML list)"),
        DeclareLaunchArgument("delay", default_value="1.0",
                              description="seconds between the subscribers' match and play"),
        Node(package="dampest_ros", executable="replay_node", name="replay_node",
             output="screen",
             parameters=[os.path.join(CONFIG, "replay_node.params.yaml"),
                         {"bag": LaunchConfiguration("bag"),
                          "rate": LaunchConfiguration("rate"), "clock": True,
                          "topics": LaunchConfiguration("topics"),
                          "delay": LaunchConfiguration("delay")}]),
        Node(package="dampest_ros", executable="preprocess_node", name="preprocess_node",
             output="screen",
             parameters=[os.path.join(CONFIG, "preprocess_node.params.yaml"), common]),
        Node(package="dampest_ros", executable="estimator_node", name="estimator_node",
             output="screen",
             parameters=[os.path.join(CONFIG, "estimator_node.params.yaml"), common]),
    ])
