"""The simulated sensor as a ROS node (``sim_camera``): thin rclpy shells over the simulator.

Imported first by every node executable: the quiet-stop signal handlers go in before the
heavy imports (see :mod:`tactile_sl_common.nodes.stop`).
"""
from tactile_sl_common.nodes.stop import install_for_executable as _install_for_executable

_install_for_executable()
