"""Signals as exceptions, held for a block (tactile_sl_common.signals).

A held signal must not be raised inside the block (it would land in a compiled kernel's
Python callback: a SystemError or a crash) but when the block ends.
"""
from __future__ import annotations

import signal

import pytest

from tactile_sl_common import signals
from tactile_sl_common.signals import Terminated

EXCEPTIONS = [(signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, Terminated)]
"""Each signal and the exception it raises under :func:`signals.as_exceptions`."""


def _send(signum: int) -> None:
    signal.raise_signal(signum)        # the handler runs before the next bytecode


@pytest.mark.parametrize("signum, raised", EXCEPTIONS)
def test_a_signal_outside_a_held_block_is_raised_at_once(signum, raised):
    reached = []
    with signals.as_exceptions():
        with pytest.raises(raised):
            _send(signum)
            reached.append("after the signal")
    assert reached == []


@pytest.mark.parametrize("signum, raised", EXCEPTIONS)
def test_a_held_signal_is_raised_when_the_outermost_block_ends(signum, raised):
    reached = []
    with signals.as_exceptions():
        with pytest.raises(raised):
            with signals.held():
                with signals.held():
                    _send(signum)
                    reached.append("inner block went on")
                reached.append("outer block went on")
        reached.append("after")
    assert reached == ["inner block went on", "outer block went on", "after"]


def test_the_second_signal_during_a_held_block_is_raised_at_once():
    reached = []
    with signals.as_exceptions():
        with pytest.raises(KeyboardInterrupt):
            with signals.held():
                _send(signal.SIGINT)
                reached.append("first held")
                _send(signal.SIGINT)
                reached.append("second held")
    assert reached == ["first held"]


def test_a_held_signal_wins_over_the_blocks_own_exception():
    with signals.as_exceptions():
        with pytest.raises(Terminated):
            with signals.held():
                _send(signal.SIGTERM)
                raise ValueError("the block failed after the signal")


def test_nothing_is_left_noted_after_a_block_and_the_handlers_are_restored():
    before = {s: signal.getsignal(s) for s in signals.HANDLED}
    with signals.as_exceptions():
        with pytest.raises(KeyboardInterrupt):
            with signals.held():
                _send(signal.SIGINT)
        with signals.held():               # a clean block after it raises nothing
            pass
    assert {s: signal.getsignal(s) for s in signals.HANDLED} == before


def test_held_changes_nothing_without_as_exceptions():
    # a library caller's (or rclpy's) handlers stay in place and act at once
    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt):
        with signals.held():
            assert signal.getsignal(signal.SIGINT) is before
            _send(signal.SIGINT)
            pytest.fail("the signal did not act at once")


def test_swapped_handlers_send_the_signal_again_after_the_block():
    got = []
    previous = signal.signal(signal.SIGTERM, lambda signum, _f: got.append(signum))
    try:
        with signals.held(swap_handlers=True):
            _send(signal.SIGTERM)
            assert got == []
        assert got == [signal.SIGTERM]
    finally:
        signal.signal(signal.SIGTERM, previous)
