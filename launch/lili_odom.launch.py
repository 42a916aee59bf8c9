"""Launch the lili_odom node with the package's parameter files (and RViz2 on request).

    ros2 launch lili_odom lili_odom.launch.py
    ros2 launch lili_odom lili_odom.launch.py use_sim_time:=true params_file:=/path/to/my.yaml
    ros2 launch lili_odom lili_odom.launch.py rviz:=true

``params_file`` is the robot file (topics, frames, extrinsics, method, QoS; default the
installed ``config/lili_odom.yaml``), ``advanced_params_file`` the tuning parameters (default
the installed ``config/lili_odom_advanced.yaml``); the robot file is applied last.

With a bag: ``ros2 bag play BAG --clock`` (or ``lili-odom play BAG``) and ``use_sim_time:=true``.

DDS: every process this launch starts gets ``FASTRTPS_DEFAULT_PROFILES_FILE`` = the
``dds_profile`` argument (default: the variable's current value, else the package's
``config/dds/fastdds.xml``, whose larger shared-memory segment lets full-resolution clouds
through; see docs/ros.md). Include the LiDAR driver in the same launch, or export the
variable for it, since the profile matters in the publishing process.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import EnvironmentVariable, LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory("lili_odom")
    default_params = os.path.join(share, "config", "lili_odom.yaml")
    default_advanced = os.path.join(share, "config", "lili_odom_advanced.yaml")
    default_profile = os.path.join(share, "config", "dds", "fastdds.xml")
    default_rviz = os.path.join(share, "rviz", "lili_odom.rviz")
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="robot parameter file (lili_odom: ros__parameters:)"),
        DeclareLaunchArgument("advanced_params_file", default_value=default_advanced,
                              description="advanced (tuning) parameter file"),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="follow /clock (bag replay)"),
        DeclareLaunchArgument("method", default_value="lili",
                              description="degeneracy detector: lili, zhang, hessian or none"),
        DeclareLaunchArgument(
            "dds_profile",
            default_value=EnvironmentVariable("FASTRTPS_DEFAULT_PROFILES_FILE",
                                              default_value=default_profile),
            description="Fast DDS XML profile for the launched processes"),
        DeclareLaunchArgument("rviz", default_value="false",
                              description="also start RViz2 with the package's view"),
        DeclareLaunchArgument("rviz_config", default_value=default_rviz,
                              description="RViz2 configuration file"),
        SetEnvironmentVariable("FASTRTPS_DEFAULT_PROFILES_FILE",
                               LaunchConfiguration("dds_profile")),
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
        Node(
            package="rviz2",
            executable="rviz2",
            name="rviz2",
            arguments=["-d", LaunchConfiguration("rviz_config")],
            parameters=[{"use_sim_time": LaunchConfiguration("use_sim_time")}],
            condition=IfCondition(LaunchConfiguration("rviz")),
        ),
    ])
