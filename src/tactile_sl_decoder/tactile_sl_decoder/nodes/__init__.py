"""Thin rclpy nodes: convert messages, declare parameters, call the library.

Imported first by every node executable: the quiet-stop signal handlers go in before the
heavy imports (see :mod:`tactile_sl_common.nodes.stop`).
"""
from tactile_sl_common.nodes.stop import install_for_executable as _install_for_executable

_install_for_executable()
