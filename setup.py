"""ament_python package definition for lili_odom.

The same file serves ``colcon build`` on a ROS 2 Jazzy install and ``pip install -e .`` in a
plain virtual environment. ROS itself (rclpy, message packages) is never an install requirement:
on machines without ROS the ``ros`` extra pulls the pip-packaged Jazzy wheels.
"""
from glob import glob

from setuptools import find_packages, setup

package_name = "lili_odom"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "benchmarks", "benchmarks.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/config/worlds", glob("config/worlds/*.yaml")),
        ("share/" + package_name + "/config/scenarios", glob("config/scenarios/*.yaml")),
        ("share/" + package_name + "/config/dds", glob("config/dds/*.xml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
        ("share/" + package_name + "/rviz", glob("rviz/*.rviz")),
        ("share/" + package_name + "/foxglove", glob("foxglove/*.json")),
    ],
    python_requires=">=3.10",
    install_requires=[
        "setuptools",
        "numpy>=1.24",
        "scipy>=1.10",
        "pandas>=1.5",
        "kiss-icp>=1.2,<2",
        "gtsam>=4.2",
        "rosbags>=0.10",
        "mcap>=1.1",
        "evo>=1.28",
        "matplotlib>=3.7",
        "rich>=13",
        "pyyaml>=6",
        "trimesh>=4",
        "embreex>=2.17",
    ],
    extras_require={
        # pip-packaged ROS 2 Jazzy for machines without a ROS install (never needed under colcon).
        "ros": [
            "ros-jazzy-rclpy",
            "ros-jazzy-common-interfaces",
            "ros-jazzy-rmw-fastrtps-cpp",
        ],
        "dev": ["pytest>=7", "hypothesis>=6"],
        # peers of the scenario suite (`lili-odom suite`); KISS-ICP is already a dependency.
        "peers": ["genz-icp>=0.3", "rko-lio>=0.4"],
        # `lili-odom suite --backend ray`: the suite's jobs as tasks on a Ray cluster.
        "cluster": ["ray>=2.40"],
        # Ouster recordings (lili-odom run RECORDING.pcap/.osf, test_ouster.py): the Ouster
        # SDK's runtime dependencies. The SDK itself pins rosbags==0.9.23, which conflicts with
        # rosbags>=0.10 above, so it is installed without its pins:
        #   pip install '.[ouster]' && pip install --no-deps ouster-sdk==1.0.1
        # (make install-ouster)
        "ouster": ["click", "more-itertools", "nanobind", "packaging", "Pillow", "prettytable",
                   "psutil", "requests", "threadpoolctl", "laspy", "zeroconf", "flask"],
    },
    zip_safe=True,
    maintainer="lili_odom maintainers",
    maintainer_email="maintainers@lili-odom.invalid",
    description="Degeneracy-aware LiDAR-inertial odometry with the LiLi detector",
    license="MIT",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "lili-odom = lili_odom.cli:main",
            "lili_odom_node = lili_odom.ros.node:main",
        ],
    },
)
