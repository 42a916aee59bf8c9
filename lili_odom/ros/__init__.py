"""The live ROS 2 node. The only package of lili_odom that imports rclpy."""
