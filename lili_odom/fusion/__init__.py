"""Degeneracy-aware LiDAR-inertial-wheel fusion (GTSAM iSAM2), pure Python, no ROS."""
from lili_odom.fusion.config import FusionConfig, LidarNoiseConfig
from lili_odom.fusion.estimator import FusionEstimator, FusionOutput, FusionStats
from lili_odom.fusion.imu import ImuBuffer, ImuNoiseConfig, make_preintegration_params
from lili_odom.fusion.subspace import split_information
from lili_odom.fusion.wheel import WheelBuffer, WheelNoiseConfig, wheel_information

__all__ = [
    "FusionConfig",
    "LidarNoiseConfig",
    "ImuNoiseConfig",
    "WheelNoiseConfig",
    "FusionEstimator",
    "FusionOutput",
    "FusionStats",
    "ImuBuffer",
    "WheelBuffer",
    "make_preintegration_params",
    "split_information",
    "wheel_information",
]
