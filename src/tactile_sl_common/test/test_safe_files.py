"""Sets of output files written all or none, with the mode a plain open() gives (issue 28)."""
from __future__ import annotations

import os

import pytest

from tactile_sl_common import safe_files
from tactile_sl_common.safe_files import OutputError, check_outputs, write_files


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def test_a_set_is_written_with_the_umask_mode(tmp_path, umask_022):
    paths = write_files(tmp_path / "new" / "dir", {"a.yaml": b"a", "b.png": b"b"})
    assert [p.read_bytes() for p in paths] == [b"a", b"b"]
    assert {p.stat().st_mode & 0o777 for p in paths} == {0o644}
    assert sorted(p.name for p in paths[0].parent.iterdir()) == ["a.yaml", "b.png"]


def test_a_target_that_is_a_folder_stops_the_whole_set_before_writing(tmp_path):
    (tmp_path / "right.yaml").mkdir()
    with pytest.raises(OutputError, match="right.yaml: it exists and is not a regular file"):
        write_files(tmp_path, {"left.yaml": b"l", "right.yaml": b"r"})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["right.yaml"]
    (tmp_path / "file").touch()
    with pytest.raises(OutputError, match="file: it is not a directory"):
        check_outputs(tmp_path / "file", ["left.yaml"])


def test_a_rename_failing_midway_puts_the_earlier_files_back(tmp_path, monkeypatch):
    (tmp_path / "left.yaml").write_bytes(b"old left")
    real = os.replace
    calls = []

    def failing(src, dst):
        calls.append(dst)
        if str(dst).endswith("right.yaml"):
            raise OSError(28, "No space left on device", str(dst))
        return real(src, dst)

    monkeypatch.setattr(safe_files.os, "replace", failing)
    with pytest.raises(OutputError, match="No space left on device; nothing written"):
        write_files(tmp_path, {"left.yaml": b"new left", "right.yaml": b"new right",
                               "coverage.png": b"png"})
    monkeypatch.undo()
    assert (tmp_path / "left.yaml").read_bytes() == b"old left"      # restored
    assert sorted(p.name for p in tmp_path.iterdir()) == ["left.yaml"]  # no temp, no backup
