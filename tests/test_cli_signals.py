"""`tactile-sl` stopped by a signal leaves nothing behind (issue 28, item 7).

SIGINT was clean (exit 130, the temporary bag removed); SIGTERM killed the process where it
stood and left ``.NAME.mcap.XXXX.tmp`` beside the target.  Both now unwind: exit 130 / 143,
no output, no temporary file.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from ros_harness import BAGS

pytestmark = pytest.mark.ros     # starts processes (the command line, no DDS)


@pytest.mark.parametrize("signum, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_replay_stopped_midway_leaves_no_temporary_file(tmp_path, signum, status):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    out = run_dir / "out.mcap"
    # an empty cache: the reference's inversion is computed (~1 s), so the signal comes
    # while the replay runs (read back from a cache, the 7 frames take 0.2 s in all).  The
    # signal waits for the end of the frame it comes in (the frame finishes and may cache
    # its reference, outside run_dir), then the replay unwinds.
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))
    proc = subprocess.Popen([sys.executable, "-m", "tactile_sl_decoder.cli", "replay",
                             str(BAGS / "two_contacts.mcap"), "-o", str(out), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env)
    try:
        deadline = time.monotonic() + 60
        while not list(run_dir.glob(".out.mcap.*.tmp")) and time.monotonic() < deadline:
            assert proc.poll() is None, proc.communicate()[0]
            time.sleep(0.02)
        assert list(run_dir.glob(".out.mcap.*.tmp")), "replay never began writing"
        # at once: the run has ~1.5 s left (the reference's inversion, then the frames);
        # 0.2 s later a loaded machine's run had once finished, and the signal came too late
        proc.send_signal(signum)
        text = proc.communicate(timeout=60)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == status, text
    assert sorted(p.name for p in run_dir.iterdir()) == [], text
    assert "Traceback" not in text, text


def _replay_raising(first: BaseException | None, wrappers: int, message: str):
    """A replay command raising ``first`` reported as CPython reports an exception set inside
    a compiled call: ``wrappers`` SystemErrors, each caused by the one before."""
    def run(_args):
        cause: BaseException | None = first
        for _ in range(wrappers):
            try:
                raise SystemError(message) from cause
            except SystemError as exc:
                cause = exc
        assert cause is not None
        raise cause
    return run


@pytest.mark.parametrize("signalled, wrappers, status, line", [
    # Ctrl-C as a numba kernel returns (seen once in ~30 signalled replays)
    ("interrupt", 1, 130, "interrupted"),
    # SIGTERM while numba unpickles a cached kernel on its first call: _numba_unpickle's
    # SystemError, then the dispatcher's (seen once in 250 signalled replays: exit 1 and a
    # traceback before)
    ("terminate", 2, 143, "terminated")])
def test_a_signal_reported_by_compiled_code_is_that_signal(monkeypatch, capsys, signalled,
                                                           wrappers, status, line):
    from tactile_sl_decoder.cli import Terminated, main, replay_cmd

    first = KeyboardInterrupt() if signalled == "interrupt" else Terminated(signal.SIGTERM)
    monkeypatch.setattr(replay_cmd, "run", _replay_raising(
        first, wrappers, "CPUDispatcher(<function knn_within>) returned a result with an "
        "exception set"))
    assert main(["replay", "in.mcap", "-o", "out.mcap"]) == status
    assert capsys.readouterr().err.strip() == line


@pytest.mark.parametrize("first, wrappers", [(None, 1), (ValueError("not a signal"), 1),
                                             (ValueError("not a signal"), 2)])
def test_a_system_error_that_reports_no_signal_stays_one(monkeypatch, first, wrappers):
    from tactile_sl_decoder.cli import main, replay_cmd

    monkeypatch.setattr(replay_cmd, "run", _replay_raising(
        first, wrappers, "returned a result with an exception set"))
    with pytest.raises(SystemError):
        main(["replay", "in.mcap", "-o", "out.mcap"])
