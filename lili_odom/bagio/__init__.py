"""rosbag2 input and output for offline runs (rosbags, no rclpy)."""
