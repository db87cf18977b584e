"""The one harness for process tests: workspace paths, domain ids, executables, logs, probes.

Every test of the workspace takes ``REPO``/``BAGS`` from here; every test that runs node
executables or an rclpy node over DDS takes its domain id (:func:`next_domain_id`), child
environment (:func:`ros_env`), executable (:func:`executable`, through the ament index),
captured log (:func:`running_node`) and in-process node (:class:`Probe`) from here, so no
test file invents its own.  rclpy is imported only when a probe is made: unit tests that
import ``REPO`` stay free of it.
"""
from __future__ import annotations

import contextlib
import itertools
import os
import pathlib
import subprocess
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterator

REPO = pathlib.Path(__file__).resolve().parents[1]
"""The workspace root (bags/, config/, install/), for every test of the workspace."""
BAGS = REPO / "bags"

# Domain ids 0..101 are safe on Linux; spread tests across them, away from env.sh's default 42.
# TACTILE_SL_TEST_DOMAINS=LO-HI confines a test session to its own range (several checkouts
# testing side by side on one machine must not discover each other's nodes).


def _domain_range() -> range:
    """This process's domain ids: the session's range, dealt out among pytest-xdist workers.

    Worker k of n takes every n-th id from the k-th, so tests running at once in different
    workers never share a domain.
    """
    spec = os.environ.get("TACTILE_SL_TEST_DOMAINS", "")
    if spec:
        lo, hi = (int(x) for x in spec.split("-"))
        if not 0 <= lo <= hi <= 101:
            raise ValueError(f"TACTILE_SL_TEST_DOMAINS={spec!r}: need LO-HI within 0-101")
        ids = range(lo, hi + 1)
    else:   # one range for the whole session (its xdist run id), not one per worker
        run = os.environ.get("PYTEST_XDIST_TESTRUNUID", "")
        ids = range(60 + (sum(run.encode()) if run else os.getpid()) % 20, 101)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")   # "gw0", "gw1", ... under `-n N`
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if worker.startswith("gw") and workers > 1:
        ids = ids[int(worker[2:]) % workers::workers]
        if len(ids) < 4:
            raise ValueError(f"TACTILE_SL_TEST_DOMAINS={spec!r}: too few ids for {workers} "
                             "pytest-xdist workers (need 4 each)")
    return ids


_domains = itertools.cycle(_domain_range())


def next_domain_id() -> int:
    """A fresh ROS_DOMAIN_ID for one test, so concurrent tests never discover each other."""
    return next(_domains)


def ros_env(domain_id: int) -> dict[str, str]:
    """Environment for a child process: localhost-only discovery, its own domain."""
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("RCUTILS_LOGGING_BUFFERED_STREAM", "0")
    env.setdefault("PYTHONUNBUFFERED", "1")   # a log read mid-test holds what was printed
    return env


def executable(package: str, name: str) -> pathlib.Path:
    """What `ros2 run PACKAGE NAME` runs: <prefix>/lib/<package>/<name> via the ament index.

    Raises (the test fails, never skips) when the workspace has not been built.
    """
    from ament_index_python.packages import get_package_prefix

    path = pathlib.Path(get_package_prefix(package)) / "lib" / package / name
    if not os.access(path, os.X_OK):
        raise FileNotFoundError(f"{path} is not an executable (was the workspace built?)")
    return path


def start_node(package: str, name: str, domain_id: int, ros_args: list[str],
               log_path: pathlib.Path) -> subprocess.Popen:
    """Start an installed node executable as its own process, output to log_path."""
    with open(log_path, "w") as log:     # the child keeps its own descriptor
        return subprocess.Popen([str(executable(package, name)), "--ros-args", *ros_args],
                                env=ros_env(domain_id), stdout=log, stderr=subprocess.STDOUT)


def start_looping_sensor(domain_id: int, node_args: list[str], bag: pathlib.Path,
                         log_dir: pathlib.Path, tag: str) -> list[subprocess.Popen]:
    """A decoder (diagnostics every 0.5 s) fed by ``replay`` looping ``bag`` at half speed.

    ``node_args`` (namespace remap, frame_prefix, ...) go to both; logs are
    ``decoder_<tag>.log`` and ``replay_<tag>.log`` in ``log_dir``.
    """
    return [start_node("tactile_sl_decoder", "decoder", domain_id,
                       [*node_args, "-p", "diagnostic_period:=0.5"],
                       log_dir / f"decoder_{tag}.log"),
            start_node("tactile_sl_camera", "replay", domain_id,
                       [*node_args, "-p", f"bag:={bag}", "-p", "loop:=true", "-p", "rate:=0.5"],
                       log_dir / f"replay_{tag}.log")]


@dataclass
class RunningNode:
    """A node process started by :func:`running_node`, with its captured stdout and stderr."""

    process: subprocess.Popen
    log_path: pathlib.Path

    def log(self) -> str:
        """Everything the node has printed so far."""
        return self.log_path.read_text(errors="replace") if self.log_path.exists() else ""

    def lines(self) -> list[str]:
        return self.log().splitlines()

    def wait_for_log(self, text: str, timeout: float,
                     spin: Callable[[], None] = lambda: time.sleep(0.05)) -> bool:
        """True once ``text`` is in the log; False at the timeout or when the node has exited."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.log():
                return True
            if self.process.poll() is not None:
                break
            spin()
        return text in self.log()


@contextlib.contextmanager
def running_node(package: str, name: str, domain_id: int, ros_args: list[str],
                 log_path: pathlib.Path) -> Iterator[RunningNode]:
    """Run an installed node for the ``with`` block, its output captured in ``log_path``.

    The node is stopped on exit, also when the block fails, and its log stays readable.
    """
    node = RunningNode(start_node(package, name, domain_id, ros_args, log_path), log_path)
    try:
        yield node
    finally:
        stop(node.process)


class Probe:
    """The test's own rclpy node: a private context on one domain, spun by the test.

    Use as a context manager (or call :meth:`close`); subscriptions and publishers are made on
    ``probe.node``.
    """

    def __init__(self, name: str, domain_id: int, namespace: str | None = None) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, namespace=namespace, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_once(self, timeout: float = 0.05) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def spin(self, seconds: float) -> None:
        """Handle callbacks for ``seconds`` (waiting in short steps)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.02, max(0.0, end - time.monotonic())))

    def spin_until(self, predicate: Callable[[], Any], timeout: float) -> bool:
        return bool(wait_until(predicate, timeout, self.spin_once))

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)

    def __enter__(self) -> "Probe":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def wait_until(predicate: Callable[[], bool], timeout: float, spin: Callable[[], None]) -> bool:
    """Call ``spin`` until ``predicate()`` holds or ``timeout`` seconds have passed."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        spin()
    return predicate()


def stop(process: subprocess.Popen, timeout: float = 10.0) -> int:
    """SIGTERM, then SIGKILL after ``timeout`` seconds; the exit code."""
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode


CHROMIUM = pathlib.Path(os.environ.get("TACTILE_SL_CHROMIUM", "/usr/bin/chromium"))
"""The distribution's Chromium (tools/setup.sh installs it); playwright downloads no browser."""
CHROMIUM_ARGS = [
    "--no-sandbox",                       # as root; the page is our own, on loopback
    "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-sync",
    # no network here: without these Chromium keeps trying (and failing) to reach services
    "--disable-background-networking", "--disable-component-update",
]


@contextlib.contextmanager
def browser_page(profile_dir: pathlib.Path, width: int = 1560, height: int = 900
                 ) -> Iterator[Any]:
    """A page of headless Chromium (a fresh profile in ``profile_dir``), via playwright.

    Raises (the test fails, never skips) when Chromium or playwright is missing.
    """
    from playwright.sync_api import sync_playwright

    if not os.access(CHROMIUM, os.X_OK):
        raise FileNotFoundError(f"{CHROMIUM} is not an executable: `make setup` as root "
                                "installs Debian's chromium (apt-get install chromium)")
    with sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            str(profile_dir), executable_path=str(CHROMIUM), headless=True,
            args=CHROMIUM_ARGS, viewport={"width": width, "height": height})
        try:
            yield context.pages[0] if context.pages else context.new_page()
        finally:
            context.close()
