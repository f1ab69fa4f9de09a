"""Independent references for the tissue models: finite elements on a boundary-fitted mesh.

- :mod:`.finite_elements` — a static punch (the particle framework's reference);
- :mod:`.creep_fe` — the twin's truth, small strain (scikit-fem);
- :mod:`.finite_strain`, :mod:`.finite_strain_push` — the same physics at finite strain
  (FElupe), for pushes that strain the tissue beyond what small strain holds.

Nothing here imports the models it checks (:mod:`hifumotion.particles`, :mod:`hifumotion.creep`).
"""

from hifumotion.reference.finite_elements import PunchedTissue, ReferenceSolution, punch_reference

__all__ = ["PunchedTissue", "ReferenceSolution", "punch_reference"]
