"""Integration-test fixtures: loopback-only DDS, per-test domains, and a DDS leak watch."""
from __future__ import annotations

import pathlib
import sys

import pytest

sys.path.insert(0, str(pathlib.Path(__file__).parent))

from dds_sniffer import DdsSniffer  # noqa: E402
from ros_harness import REPO, next_domain_id  # noqa: E402

_sniffer: DdsSniffer | None = None


def pytest_configure(config: pytest.Config) -> None:
    """Start watching non-loopback interfaces for DDS traffic for the whole session."""
    global _sniffer
    _sniffer = DdsSniffer().start()


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Fail the run if any RTPS packet left the loopback interface while tests ran."""
    if _sniffer is None:
        return
    _sniffer.stop()
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if not _sniffer.available:
        line = f"DDS leak watch not active: {_sniffer.reason}"
    elif _sniffer.leaks:
        line = "DDS LEAK: " + "; ".join(_sniffer.leaks)
        session.exitstatus = 1
    else:
        line = (f"DDS leak watch: 0 RTPS packets on non-loopback interfaces "
                f"({_sniffer.packets_seen} frames inspected)")
    if reporter is not None:
        reporter.write_line("")
        reporter.write_line(line)


@pytest.fixture
def dds_sniffer() -> DdsSniffer:
    assert _sniffer is not None
    return _sniffer


@pytest.fixture
def domain_id() -> int:
    return next_domain_id()


@pytest.fixture
def repo() -> pathlib.Path:
    return REPO
