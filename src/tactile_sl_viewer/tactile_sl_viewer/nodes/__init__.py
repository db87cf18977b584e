"""The ``viewer`` node (rclpy): subscriptions and parameters around the web library.

Imported first by the executable: the quiet-stop signal handlers go in before the heavy
imports (see :mod:`tactile_sl_common.nodes.stop`).
"""
import os
import sys

from tactile_sl_common.nodes import stop as _stop

if os.path.basename(sys.argv[0] if sys.argv else "") == "viewer":
    _stop.install()
