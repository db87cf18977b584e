"""Stopping a node executable: Ctrl-C and SIGTERM only ask; the runner stops between callbacks.

rclpy's own signal handlers shut the context down at once, so a callback that is halfway
through a frame then publishes on an invalid context ("publisher's context is invalid",
RCLError) and spinning raises ExternalShutdownException.  Instead, the executables handle
SIGINT and SIGTERM themselves: the handler only records the request; the runner leaves the
spin loop after the current callback, joins the node's threads, destroys the node and shuts
rclpy down, and the process exits 0.  Installed as early as the package is imported by an
executable (see ``nodes/__init__.py``), so a signal during start-up is honoured too.
"""
from __future__ import annotations

import os
import signal
import sys
import threading

EXECUTABLES = frozenset({"decoder", "symbol_extractor", "symbol_classifier", "replay",
                         "sim_camera", "stereo_camera"})

_requested = threading.Event()
_installed = False


def _on_signal(signum: int, _frame: object) -> None:
    _requested.set()


def install() -> None:
    """Route SIGINT and SIGTERM to :func:`requested` (main thread only; idempotent)."""
    global _installed
    if _installed or threading.current_thread() is not threading.main_thread():
        return
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    _installed = True


def install_for_executable() -> None:
    """Install the handlers when this process is one of the node executables."""
    if os.path.basename(sys.argv[0] if sys.argv else "") in EXECUTABLES:
        install()


def requested() -> bool:
    """True once Ctrl-C or SIGTERM arrived (or :func:`request` was called)."""
    return _requested.is_set()


def request() -> None:
    """Ask for a stop from inside the process (e.g. a replay that reached its end)."""
    _requested.set()


def wait(seconds: float) -> bool:
    """Sleep up to ``seconds``, returning True early when a stop is requested."""
    return _requested.wait(seconds)
