"""One way to run a node: spin until asked to stop; a configuration error is one fatal line.

Shared by the executables of both packages so that a bad parameter, calibration file or
weights file ends every node the same way: a FATAL log line naming the problem and exit
status 1, never a traceback.  Ctrl-C and SIGTERM, at any moment (during start-up, in the
middle of a frame, at the end of a replay), end it quietly with status 0: the signal only
sets a flag (:mod:`.stop`), the current callback finishes, the node's threads are joined in
its ``destroy_node`` and only then is rclpy shut down.  Once the node is made, everything
start-up left is frozen out of the garbage collector's reach (:mod:`tactile_sl_common.heap`:
no full collection of tens of milliseconds between two frames).
"""
from __future__ import annotations

import os
from typing import Callable, TypeVar

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

try:
    from rclpy.experimental import EventsExecutor
except ImportError:   # an rclpy without it: the classic executor
    EventsExecutor = None  # type: ignore[assignment]  # checked where used

from tactile_sl_common.heap import freeze_long_lived
from tactile_sl_common.nodes import stop

ConfigurationErrors = tuple[type[BaseException], ...]
NodeT = TypeVar("NodeT", bound=Node)   # so that ``finished`` sees the node's own class


def make_executor() -> Executor:
    """The executor every node runs in: rclpy's events executor where this rclpy has it.

    It queues ready entities in C++ instead of rebuilding a wait set in Python at every
    wake-up: a node receiving stereo images spends about a third less CPU per frame outside
    its callbacks (measured: 2.1 -> 1.4 ms per stereo frame at 60 Hz for the four image and
    camera_info subscriptions). ``TACTILE_SL_EXECUTOR=single`` picks the classic
    single-threaded one.
    """
    if os.environ.get("TACTILE_SL_EXECUTOR", "events") != "single" and (
            EventsExecutor is not None):
        return EventsExecutor()
    return SingleThreadedExecutor()


def run_node(make_node: Callable[[], NodeT], name: str,
             fatal: ConfigurationErrors = (ValueError, OSError, RuntimeError),
             args: list[str] | None = None,
             finished: Callable[[NodeT], bool] | None = None) -> None:
    """Create the node with ``make_node`` and spin it until a stop is requested.

    ``fatal`` errors (while creating the node or in a callback) exit with status 1 after one
    FATAL line; ``finished(node)`` returning True ends the spin normally (status 0).
    """
    stop.install()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node: NodeT | None = None
    status = 0
    # also ParameterException: a value out of range, a wrong type (a named tuple, as mypy
    # cannot read a starred tuple written in the except clause itself)
    configuration_errors: ConfigurationErrors = (*fatal, ParameterException)
    executor = make_executor()
    try:
        if not stop.requested():
            node = make_node()
            executor.add_node(node)
            freeze_long_lived()     # start-up's objects: out of every later collection
            while (not stop.requested() and rclpy.ok()
                   and not (finished is not None and finished(node))):
                executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except configuration_errors as exc:
        if not stop.requested():     # an error while stopping is not a configuration error
            logger = node.get_logger() if node is not None else rclpy.logging.get_logger(name)
            logger.fatal(str(exc))
            status = 1
    finally:
        try:
            if node is not None:
                executor.remove_node(node)
                node.destroy_node()
        finally:
            executor.shutdown(timeout_sec=1.0)
            rclpy.try_shutdown()
    if status:
        raise SystemExit(status)
