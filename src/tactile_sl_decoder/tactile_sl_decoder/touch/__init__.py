"""Touch stage: displacement, traction, wrench and contact from decoded points (no rclpy).

points (left optical frame) -> :mod:`.reference` (untouched state, pad pose) ->
:mod:`.displacement` (per-cell 3-D displacement in the pad frame) -> :mod:`.traction`
(linear-elastic inversion) -> :mod:`.contact` (contact state, depth map).
:class:`.stage.TouchStage` composes them for the decoder node and ``tactile-sl replay``.
"""
