"""Helpers for tests that run real node executables over DDS, confined to loopback."""
from __future__ import annotations

import itertools
import os
import pathlib
import subprocess
import time
from typing import Callable

from ament_index_python.packages import get_package_prefix

REPO = pathlib.Path(__file__).resolve().parents[1]
"""The workspace root (bags/, config/, install/), for every test of the workspace."""
BAGS = REPO / "bags"

# Domain ids 0..101 are safe on Linux; spread tests across them, away from env.sh's default 42.
_domains = itertools.cycle(range(60 + os.getpid() % 20, 101))


def next_domain_id() -> int:
    """A fresh ROS_DOMAIN_ID for one test, so concurrent tests never discover each other."""
    return next(_domains)


def ros_env(domain_id: int) -> dict[str, str]:
    """Environment for a child process: localhost-only discovery, its own domain."""
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("RCUTILS_LOGGING_BUFFERED_STREAM", "0")
    return env


def executable(package: str, name: str) -> pathlib.Path:
    """What `ros2 run PACKAGE NAME` runs: <prefix>/lib/<package>/<name> via the ament index."""
    path = pathlib.Path(get_package_prefix(package)) / "lib" / package / name
    if not os.access(path, os.X_OK):
        raise FileNotFoundError(f"{path} is not an executable (was the workspace built?)")
    return path


def start_node(package: str, name: str, domain_id: int, ros_args: list[str],
               log_path: pathlib.Path) -> subprocess.Popen:
    """Start an installed node executable as its own process, output to log_path."""
    log = open(log_path, "w")
    return subprocess.Popen([str(executable(package, name)), "--ros-args", *ros_args],
                            env=ros_env(domain_id), stdout=log, stderr=subprocess.STDOUT)


def wait_until(predicate: Callable[[], bool], timeout: float, spin: Callable[[], None]) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        spin()
    return predicate()


def stop(process: subprocess.Popen, timeout: float = 10.0) -> int:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode
