"""Launch the lili_odom node with the package's parameter files.

    ros2 launch lili_odom lili_odom.launch.py
    ros2 launch lili_odom lili_odom.launch.py use_sim_time:=true params_file:=/path/to/my.yaml

``params_file`` is the robot file (topics, frames, extrinsics, method, QoS; default the
installed ``config/lili_odom.yaml``), ``advanced_params_file`` the tuning parameters (default
the installed ``config/lili_odom_advanced.yaml``); the robot file is applied last.

With a bag: ``ros2 bag play BAG --clock`` (or ``lili-odom play BAG``) and ``use_sim_time:=true``.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    config_dir = os.path.join(get_package_share_directory("lili_odom"), "config")
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=os.path.join(config_dir,
                                                                        "lili_odom.yaml"),
                              description="robot parameter file (lili_odom: ros__parameters:)"),
        DeclareLaunchArgument("advanced_params_file",
                              default_value=os.path.join(config_dir, "lili_odom_advanced.yaml"),
                              description="advanced (tuning) parameter file"),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="follow /clock (bag replay)"),
        DeclareLaunchArgument("method", default_value="lili",
                              description="degeneracy detector: lili, zhang, hessian or none"),
        Node(
            package="lili_odom",
            executable="lili_odom_node",
            name="lili_odom",
            output="screen",
            parameters=[LaunchConfiguration("advanced_params_file"),
                        LaunchConfiguration("params_file"),
                        {"use_sim_time": LaunchConfiguration("use_sim_time"),
                         "pipeline.method": LaunchConfiguration("method")}],
        ),
    ])
