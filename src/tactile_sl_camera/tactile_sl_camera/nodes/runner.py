"""One way to run a node: spin until shutdown; a configuration error is one fatal line.

Shared by the executables of both packages so that a bad parameter, calibration file or
weights file ends every node the same way: a FATAL log line naming the problem and exit
status 1, never a traceback; Ctrl-C and external shutdown end it quietly.
"""
from __future__ import annotations

from typing import Callable

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

ConfigurationErrors = tuple[type[BaseException], ...]


def run_node(make_node: Callable[[], Node], name: str,
             fatal: ConfigurationErrors = (ValueError, OSError, RuntimeError),
             args: list[str] | None = None) -> None:
    """Create the node with ``make_node`` and spin it; ``fatal`` errors exit with status 1."""
    rclpy.init(args=args)
    node = None
    try:
        node = make_node()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except fatal as exc:
        logger = node.get_logger() if node is not None else rclpy.logging.get_logger(name)
        logger.fatal(str(exc))
        raise SystemExit(1) from None
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
