"""cdpr_control: the cable robot models and controllers as a pure library (no rclpy); ROS nodes live in cdpr_control.nodes."""
