"""Integration-test fixtures: loopback-only DDS, per-test domains, and a DDS leak watch."""
from __future__ import annotations

import contextlib
import itertools
import pathlib
import sys
from dataclasses import dataclass
from typing import Callable, Iterator

import pytest

sys.path.insert(0, str(pathlib.Path(__file__).parent))

from dds_sniffer import DdsSniffer  # noqa: E402
from ros_harness import REPO, Probe, RunningNode, next_domain_id, running_node  # noqa: E402

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


@dataclass
class DecoderGraph:
    """The test's probe node and a ``start(*ros_args)`` for decoder processes beside it."""

    probe: Probe
    start: Callable[..., RunningNode]
    domain_id: int

    @property
    def node(self):
        return self.probe.node

    def spin_until(self, predicate: Callable[[], object], timeout: float) -> bool:
        return self.probe.spin_until(predicate, timeout)

    def spin(self, seconds: float) -> None:
        self.probe.spin(seconds)

    def spin_once(self) -> None:
        self.probe.spin_once()


@pytest.fixture
def ros(tmp_path: pathlib.Path, domain_id: int) -> Iterator[DecoderGraph]:
    """A probe node on a fresh domain; ``start`` runs the installed decoder in /tactile there.

    Each decoder's output goes to ``tmp_path/decoder<n>.log``; every one is stopped before the
    probe closes.
    """
    numbers = itertools.count()
    with Probe("decoder_test", domain_id) as probe, contextlib.ExitStack() as decoders:
        def start(*ros_args: str) -> RunningNode:
            log = tmp_path / f"decoder{next(numbers)}.log"
            return decoders.enter_context(running_node(
                "tactile_sl_decoder", "decoder", domain_id,
                ["-r", "__ns:=/tactile", "-p", "warn_period:=0.0", *ros_args], log))
        yield DecoderGraph(probe, start, domain_id)
