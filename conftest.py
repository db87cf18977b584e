"""Workspace pytest setup: loopback DDS for every rclpy process, the shared test harness.

tests/ is put on sys.path so that every test (tests/ and each package's test/) takes the
workspace paths and the process helpers from one place, ``tests/ros_harness.py``.
"""
import os
import sys

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(50 + os.getpid() % 40))
os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = os.path.join(  # even after robot-mode env.sh
    os.path.dirname(os.path.abspath(__file__)), "config", "fastdds_loopback.xml")

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "tests"))
