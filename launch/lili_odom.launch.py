"""Launch the lili_odom node with the package's parameter file.

    ros2 launch lili_odom lili_odom.launch.py
    ros2 launch lili_odom lili_odom.launch.py use_sim_time:=true params_file:=/path/to/my.yaml

With a bag: ``ros2 bag play BAG --clock`` (or ``lili-odom play BAG``) and ``use_sim_time:=true``.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    default_params = os.path.join(get_package_share_directory("lili_odom"), "config",
                                  "lili_odom.yaml")
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="ROS 2 parameter file (lili_odom: ros__parameters:)"),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="follow /clock (bag replay)"),
        DeclareLaunchArgument("method", default_value="lili",
                              description="degeneracy detector: lili, zhang, hessian or none"),
        Node(
            package="lili_odom",
            executable="lili_odom_node",
            name="lili_odom",
            output="screen",
            parameters=[LaunchConfiguration("params_file"),
                        {"use_sim_time": LaunchConfiguration("use_sim_time"),
                         "pipeline.method": LaunchConfiguration("method")}],
        ),
    ])
