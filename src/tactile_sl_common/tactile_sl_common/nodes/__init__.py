"""The rclpy helpers every node uses: parameters, the runner, the quiet stop, message builders.

:mod:`.parameters` (described, ranged, validated parameters; QoS parameters),
:mod:`.runner` (spin until asked to stop; a configuration error is one FATAL line),
:mod:`.stop` (Ctrl-C and SIGTERM only ask) and :mod:`.messages` (rclpy messages from the
libraries' field dicts).  Nothing is imported here: an executable's own ``nodes`` package
installs the quiet-stop handlers before its heavy imports.
"""
