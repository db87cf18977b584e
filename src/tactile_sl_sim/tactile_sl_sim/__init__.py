"""Physically grounded simulator of the tactile sensor: optics, pad mechanics, ray casting.

Import the modules themselves (``tactile_sl_sim.render.Renderer``, ``tactile_sl_sim.scenes``,
...): this package file imports nothing, so that the ``sim_camera`` executable installs its
quiet-stop handlers (:mod:`tactile_sl_sim.nodes`) before the heavy imports.
"""
