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
    out = tmp_path / "out.mcap"
    # an empty cache: the reference's inversion is computed (~1 s), so the signal comes
    # while the replay runs (read back from a cache, the 7 frames take 0.2 s in all)
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))
    proc = subprocess.Popen([sys.executable, "-m", "tactile_sl_decoder.cli", "replay",
                             str(BAGS / "two_contacts.mcap"), "-o", str(out), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env)
    try:
        deadline = time.monotonic() + 60
        while not list(tmp_path.glob(".out.mcap.*.tmp")) and time.monotonic() < deadline:
            assert proc.poll() is None, proc.communicate()[0]
            time.sleep(0.02)
        assert list(tmp_path.glob(".out.mcap.*.tmp")), "replay never began writing"
        # at once: the run has ~1.5 s left (the reference's inversion, then the frames);
        # 0.2 s later a loaded machine's run had once finished, and the signal came too late
        proc.send_signal(signum)
        text = proc.communicate(timeout=60)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == status, text
    assert sorted(p.name for p in tmp_path.iterdir()) == [], text
    assert "Traceback" not in text, text


def test_an_interrupt_reported_by_a_compiled_kernel_is_an_interrupt(monkeypatch, capsys):
    """Ctrl-C as a numba kernel returns comes back as a SystemError caused by the interrupt
    (seen once in ~30 signalled replays): exit 130 and one line, not a traceback."""
    from tactile_sl_decoder.cli import main, replay_cmd

    def interrupted_in_a_kernel(_args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("CPUDispatcher(<function knn_within>) returned a result with "
                              "an exception set") from exc

    monkeypatch.setattr(replay_cmd, "run", interrupted_in_a_kernel)
    assert main(["replay", "in.mcap", "-o", "out.mcap"]) == 130
    assert capsys.readouterr().err.strip() == "interrupted"

    def broken(_args):
        raise SystemError("a SystemError of its own")

    monkeypatch.setattr(replay_cmd, "run", broken)
    with pytest.raises(SystemError):
        main(["replay", "in.mcap", "-o", "out.mcap"])


def test_a_signal_while_numba_loads_a_cached_kernel_is_a_signal(monkeypatch, capsys):
    """SIGTERM while numba unpickles a cached kernel on its first call: the handler's
    exception is the cause of ``_numba_unpickle``'s SystemError, itself the cause of the
    dispatcher's (seen once in 250 signalled replays: exit 1 and a traceback before)."""
    from tactile_sl_decoder.cli import Terminated, main, replay_cmd

    def terminated_while_loading(_args):
        try:
            try:
                raise Terminated(signal.SIGTERM)
            except Terminated as exc:
                raise SystemError("<function _numba_unpickle> returned a result with an "
                                  "exception set") from exc
        except SystemError as exc:
            raise SystemError("CPUDispatcher(<function _plane_thresholds>) returned a "
                              "result with an exception set") from exc

    monkeypatch.setattr(replay_cmd, "run", terminated_while_loading)
    assert main(["replay", "in.mcap", "-o", "out.mcap"]) == 143
    assert capsys.readouterr().err.strip() == "terminated"

    def wrapped_error(_args):
        try:
            raise ValueError("not a signal")
        except ValueError as exc:
            raise SystemError("returned a result with an exception set") from exc

    monkeypatch.setattr(replay_cmd, "run", wrapped_error)
    with pytest.raises(SystemError):
        main(["replay", "in.mcap", "-o", "out.mcap"])
