"""File input/output that knows nothing of ROS."""
