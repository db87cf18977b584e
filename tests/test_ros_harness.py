"""The harness's domain ids: tests running at once in pytest-xdist workers never share one."""
from __future__ import annotations

import pytest

import ros_harness


def _ids(monkeypatch: pytest.MonkeyPatch, spec: str, worker: str, count: int) -> list[int]:
    monkeypatch.setenv("TACTILE_SL_TEST_DOMAINS", spec)
    if worker:
        monkeypatch.setenv("PYTEST_XDIST_WORKER", worker)
        monkeypatch.setenv("PYTEST_XDIST_WORKER_COUNT", str(count))
        monkeypatch.setenv("PYTEST_XDIST_TESTRUNUID", "0f3c9a")
    else:
        monkeypatch.delenv("PYTEST_XDIST_WORKER", raising=False)
        monkeypatch.delenv("PYTEST_XDIST_WORKER_COUNT", raising=False)
    return list(ros_harness._domain_range())


def test_one_process_takes_the_whole_range(monkeypatch):
    assert _ids(monkeypatch, "46-69", "", 1) == list(range(46, 70))


@pytest.mark.parametrize("spec", ["46-69", ""])
def test_workers_deal_out_the_range_without_overlap(monkeypatch, spec):
    first = _ids(monkeypatch, spec, "gw0", 2)
    second = _ids(monkeypatch, spec, "gw1", 2)
    assert not set(first) & set(second)
    assert len(first) >= 4 and len(second) >= 4
    assert all(0 <= d <= 101 and d != 42 for d in first + second)
    if spec:
        assert sorted(first + second) == list(range(46, 70))


def test_too_narrow_a_range_for_the_workers_is_an_error(monkeypatch):
    with pytest.raises(ValueError, match="too few ids for 3"):
        _ids(monkeypatch, "46-52", "gw2", 3)
