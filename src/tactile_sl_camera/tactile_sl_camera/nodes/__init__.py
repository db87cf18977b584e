"""Thin rclpy nodes: convert messages, declare parameters, call the library."""
