"""Workspace pytest setup: loopback DDS for every rclpy process, the shared test harness.

tests/ is put on sys.path so that every test (tests/ and each package's test/) takes the
workspace paths and the process helpers from one place, ``tests/ros_harness.py``.
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "tests"))

from ros_harness import REPO, next_domain_id  # noqa: E402

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(next_domain_id()))
os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(  # even after robot-mode env.sh
    REPO / "config" / "fastdds_loopback.xml")
