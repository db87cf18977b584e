"""Clean lifecycle (issue 12, finding 5): every executable exits 0 on Ctrl-C and SIGTERM.

Signals are sent at several moments: during start-up (imports, rendering, loading the
classifier), while running (the decoder in the middle of frames fed by a looping replay)
and at the end of a replay.  Every process must exit with status 0 and log no traceback,
no FATAL line, no ExternalShutdownException and no "context is invalid".  All processes run
at once (each in its own DDS domain, a replay+decoder pair sharing one) to keep it quick.
"""
from __future__ import annotations

import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from ros_harness import REPO, next_domain_id, start_node

pytestmark = pytest.mark.ros

BAD = ("Traceback", "FATAL", "ExternalShutdownException", "context is invalid", "RCLError")


@dataclass
class Case:
    name: str
    package: str
    executable: str
    params: dict[str, str]
    sig: int | None            # None: the process ends by itself
    after_s: float = 0.0       # seconds after start ...
    after_log: str = ""        # ... after this text appears in its log (default: after the
    #                            stop handlers are installed, see _handles_sigterm)
    domain: int = 0
    proc: subprocess.Popen | None = None
    log: Path | None = None
    sent: bool = False
    notes: list[str] = field(default_factory=list)


def _handles_sigterm(pid: int) -> bool:
    """True once the process caught SIGTERM: the executable's stop handlers are installed.

    They go in when the package is imported, before rclpy, the node and its files; a
    signal before that (the bare interpreter starting) is outside the program's reach.
    """
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    for line in status.splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    return False


def _small_bag(path: Path, frames: int = 3) -> Path:
    from tactile_sl_common.bag_io import BagReader, BagWriter

    stamps: list[int] = []
    with BagWriter(path) as out:
        for raw in BagReader(REPO / "bags" / "edge.mcap").raw_messages():
            if raw.log_time_ns not in stamps:
                if len(stamps) == frames:
                    break
                stamps.append(raw.log_time_ns)
            out.write_raw(raw.topic, raw.schema_name, raw.data, raw.log_time_ns)
    return path


def test_every_executable_exits_0_on_sigint_and_sigterm(tmp_path):
    bag = str(_small_bag(tmp_path / "small.mcap"))
    looping = {"bag": bag, "loop": "true", "restamp": "true", "rate": "1.0"}
    pair = next_domain_id()
    cases = [
        Case("replay-start-term", "tactile_sl_camera", "replay", {"bag": bag}, signal.SIGTERM,
             0.4),
        Case("replay-mid-int", "tactile_sl_camera", "replay", dict(looping), signal.SIGINT,
             0.5, "replaying"),
        Case("replay-mid-term", "tactile_sl_camera", "replay", dict(looping), signal.SIGTERM,
             6.0, "replaying", domain=pair),
        Case("replay-end", "tactile_sl_camera", "replay", {"bag": bag, "rate": "0.0"}, None),
        Case("decoder-start-int", "tactile_sl_decoder", "decoder", {}, signal.SIGINT, 0.0),
        Case("decoder-start-term", "tactile_sl_decoder", "decoder", {}, signal.SIGTERM, 1.0),
        Case("decoder-midframe-term", "tactile_sl_decoder", "decoder", {}, signal.SIGTERM,
             2.5, "decoder ready", domain=pair),
        Case("sim-start-term", "tactile_sl_sim", "sim_camera", {}, signal.SIGTERM, 0.5),
        Case("sim-running-int", "tactile_sl_sim", "sim_camera", {}, signal.SIGINT, 0.5,
             "simulating"),
        Case("stereo-start-int", "tactile_sl_camera", "stereo_camera",
             {"left_device": str(tmp_path / "none.avi"), "right_device":
              str(tmp_path / "none2.avi")}, signal.SIGINT, 0.0),
        Case("stereo-running-term", "tactile_sl_camera", "stereo_camera",
             {"left_device": str(tmp_path / "none.avi"), "right_device":
              str(tmp_path / "none2.avi"), "reopen_interval": "0.2"}, signal.SIGTERM, 0.5,
             "cannot be opened"),
        Case("extractor-term", "tactile_sl_decoder", "symbol_extractor", {}, signal.SIGTERM,
             0.2),
        Case("classifier-int", "tactile_sl_decoder", "symbol_classifier", {}, signal.SIGINT,
             0.5),
    ]
    try:
        _run_cases(cases, tmp_path)
    finally:
        for case in cases:
            if case.proc is not None and case.proc.poll() is None:
                case.proc.kill()
                case.proc.wait()
    failures = []
    for case in cases:
        rc = case.proc.returncode
        text = case.log.read_text(errors="replace")
        bad = [b for b in BAD if b in text]
        if case.sig is not None and not case.sent:
            failures.append(f"{case.name}: exited (rc {rc}) before the signal\n{text[-1500:]}")
        elif rc != 0 or bad:
            failures.append(f"{case.name}: rc {rc}, {bad}\n{text[-1500:]}")
    assert not failures, "\n\n".join(failures)


def _run_cases(cases: list[Case], tmp_path: Path) -> None:
    for case in cases:
        case.domain = case.domain or next_domain_id()
        case.log = tmp_path / f"{case.name}.log"
        args = ["-r", "__ns:=/tactile"]
        for key, value in case.params.items():
            args += ["-p", f"{key}:={value}"]
        case.proc = start_node(case.package, case.executable, case.domain, args, case.log)
    ready_at: dict[str, float] = {}
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        pending = False
        for case in cases:
            if case.sig is None or case.sent or case.proc.poll() is not None:
                continue
            pending = True
            now = time.monotonic()
            if case.name not in ready_at:
                if (case.after_log in case.log.read_text(errors="replace") if case.after_log
                        else _handles_sigterm(case.proc.pid)):
                    ready_at[case.name] = now
                continue
            due = ready_at[case.name] + case.after_s
            if now >= due:
                case.proc.send_signal(case.sig)
                case.sent = True
        if not pending:
            break
        time.sleep(0.05)
    for case in cases:
        try:
            case.proc.wait(timeout=max(1.0, deadline + 20 - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
