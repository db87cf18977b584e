"""Workspace pytest setup: every rclpy process the tests start stays on loopback DDS."""
import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(50 + os.getpid() % 40))
os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = os.path.join(  # even after robot-mode env.sh
    os.path.dirname(os.path.abspath(__file__)), "config", "fastdds_loopback.xml")
