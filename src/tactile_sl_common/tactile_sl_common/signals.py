"""Ctrl-C and SIGTERM as exceptions, held while compiled code must not be cut short.

A command-line tool wants both signals to unwind like an exception, so every ``finally``
runs and no temporary output is left behind (:func:`as_exceptions`).  But a Python signal
handler runs wherever the interpreter next executes bytecode, and that includes the Python
callbacks of compiled code: numba's ``_numba_unpickle`` as a cached kernel loads or raises,
a callback inside OpenCV or torch.  An exception raised there comes back to C code that may
not check for it: CPython then reports a SystemError "returned a result with an exception
set", and code that goes on with the NULL it got crashes the process (exit -11, seen once
in a CI run of ``tactile-sl replay`` stopped by SIGINT).

So a frame's work runs inside :func:`held`: a signal that comes then is noted and raised
when the block ends, in plain Python, where unwinding is safe (a frame takes ~0.1 s, the
first one, which builds the touch reference, ~1-2 s).  A second signal of the same kind
during the block is raised at once: a user who presses Ctrl-C twice gets out regardless.

Without :func:`as_exceptions` (a ROS node: rclpy owns SIGINT; a library caller), ``held``
leaves the handlers alone unless asked to swap them (:class:`~tactile_sl_common.bag_io.
BagWriter` creating its temporary file).  Main thread only: Python runs handlers there.
"""
from __future__ import annotations

import contextlib
import signal
import threading
from typing import Any, Iterator

HANDLED = (signal.SIGINT, signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C's KeyboardInterrupt.

    So every ``finally`` runs and every temporary output (``BagWriter``, ``atomic_path``)
    is removed, instead of the process dying where it stands.
    """


class _State:
    """The handlers installed by :func:`as_exceptions` and the signals held for now."""

    installed = False
    depth = 0                       # nesting of :func:`held` blocks
    noted: list[int] = []           # signals that came during them, in order, once each


def _exception_for(signum: int) -> KeyboardInterrupt:
    return Terminated(signum) if signum == signal.SIGTERM else KeyboardInterrupt()


def _handler(signum: int, _frame: Any) -> None:
    if _State.depth > 0 and signum not in _State.noted:
        _State.noted.append(signum)           # raised when the held block ends
        return
    raise _exception_for(signum)              # not held, or the second one: at once


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def as_exceptions() -> Iterator[None]:
    """SIGINT raises KeyboardInterrupt and SIGTERM :class:`Terminated` for the block.

    Main thread only (elsewhere the block runs unchanged).  The previous handlers are back
    afterwards.
    """
    if not _main_thread() or _State.installed:
        yield
        return
    previous = {s: signal.signal(s, _handler) for s in HANDLED}
    _State.installed, _State.depth, _State.noted = True, 0, []
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        _State.installed, _State.depth, _State.noted = False, 0, []


@contextlib.contextmanager
def held(swap_handlers: bool = False) -> Iterator[None]:
    """SIGINT and SIGTERM that come during the block are raised when it ends.

    Under :func:`as_exceptions` (a command-line tool) the signal is noted and, after the
    outermost held block, raised as its exception (even if the block raised: the user asked
    to stop).  Otherwise nothing changes, unless ``swap_handlers``: then the Python handlers
    are replaced for the block by ones that note the signal, and a noted signal is sent
    again after it to the handlers that were there (not a signal mask: another thread would
    take the signal and the main thread run its handler at once).  Handlers installed
    outside Python (``getsignal`` is None) are never swapped.
    """
    if not _main_thread():
        yield
        return
    if _State.installed:
        _State.depth += 1
        try:
            yield
        finally:
            _State.depth -= 1
            if _State.depth == 0 and _State.noted:
                first, _State.noted = _State.noted[0], []
                raise _exception_for(first)
        return
    if not swap_handlers or any(signal.getsignal(s) is None for s in HANDLED):
        yield
        return
    noted: list[int] = []

    def note(signum: int, _frame: Any) -> None:
        noted.append(signum)

    previous = {s: signal.signal(s, note) for s in HANDLED}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        for again in dict.fromkeys(noted):
            signal.raise_signal(again)
