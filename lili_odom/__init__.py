"""lili_odom: degeneracy-aware LiDAR-inertial odometry (pure-Python core, ROS shell in ``ros``)."""

__version__ = "0.1.0"
