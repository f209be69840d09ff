"""ROS 2 side: the rclpy node and the conversion of pipeline results to messages."""
