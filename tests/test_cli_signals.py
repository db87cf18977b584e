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
        time.sleep(0.2)                                    # mid-frame
        proc.send_signal(signum)
        text = proc.communicate(timeout=60)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == status, text
    assert sorted(p.name for p in tmp_path.iterdir()) == [], text
    assert "Traceback" not in text, text
