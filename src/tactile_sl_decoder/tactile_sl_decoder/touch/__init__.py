"""Touch stage: displacement, traction, wrench and contact from decoded points (no rclpy).

Stage 5, points -> touch. points (left optical frame) -> :mod:`.reference` (untouched
state, pad pose; per-cell 3-D displacement in the pad frame is taken against it in
:mod:`.stage`) -> :mod:`.traction` (linear-elastic inversion) -> :mod:`.contact` (contact
state, depth map) -> :mod:`.slip` (how close the contact pressing hardest is to sliding:
Mindlin's partial-slip field fitted by :mod:`.mindlin_fit` with the response tables of
:mod:`.hertz_response`). :class:`.stage.TouchStage` composes them for the decoder node and
``tactile-sl replay``; :mod:`.messages` turns its results into message dicts.
"""
