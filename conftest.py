"""Workspace pytest setup: loopback DDS for every rclpy process, the shared test harness.

tests/ is put on sys.path so that every test (tests/ and each package's test/) takes the
workspace paths and the process helpers from one place, ``tests/ros_harness.py``.
"""
import atexit
import os
import shutil
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "tests"))

from ros_harness import REPO, next_domain_id  # noqa: E402

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(next_domain_id()))
os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(  # even after robot-mode env.sh
    REPO / "config" / "fastdds_loopback.xml")
# Caches of this session's own (the touch stage's stored inversions, docs/touch.md): no test
# reads what an earlier session, or the user's own nodes, left in ~/.cache.
os.environ["XDG_CACHE_HOME"] = tempfile.mkdtemp(prefix="tactile_sl_test_cache-")
atexit.register(shutil.rmtree, os.environ["XDG_CACHE_HOME"], True)
