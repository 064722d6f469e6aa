"""ROS 2 nodes (rclpy): message and parameter conversion only, one node per module."""
