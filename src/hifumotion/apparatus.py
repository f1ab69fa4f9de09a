"""The apparatus' nominal values, once: the pushing bar's geometry and control, the friction of
the tissue on the floor and the bar's face.

A scene (:class:`~hifumotion.scene.BarConfig`, ``PhysicsConfig``), an observed
experiment's ``setup.json`` (:class:`~hifumotion.observed.setup.BarSetup`) and the fitted model
(:class:`~hifumotion.estimation.settings.ModelSettings`) default to these, so the three agree
unless a user says otherwise. Light: reading it imports nothing.
"""

from __future__ import annotations

#: Radius of the cylindrical bar, its flat pushing end (mm).
BAR_RADIUS_MM = 6.0
#: Length of the bar (mm).
BAR_LENGTH_MM = 12.0
#: Rounding of the edge of the bar's pushing end (mm): a machined bar's edge break.
BAR_EDGE_RADIUS_MM = 0.5
#: The unit vector the bar points and pushes along: down onto the tissue.
BAR_DIRECTION = (0.0, -1.0, 0.0)
#: What drives the bar: a force of known shape (its travel a result), or a travel ("travel").
BAR_CONTROL = "force"
#: Coulomb friction of the tissue on the floor and on the bar's face (the operator's estimate).
FRICTION = 0.5

__all__ = ["BAR_CONTROL", "BAR_DIRECTION", "BAR_EDGE_RADIUS_MM", "BAR_LENGTH_MM", "BAR_RADIUS_MM", "FRICTION"]
