"""Independent references for the tissue models: finite elements on a boundary-fitted mesh.

Nothing here imports the models it checks (:mod:`hifumotion.particles`, :mod:`hifumotion.creep`).
"""

from hifumotion.reference.finite_elements import PunchedTissue, ReferenceSolution, punch_reference

__all__ = ["PunchedTissue", "ReferenceSolution", "punch_reference"]
