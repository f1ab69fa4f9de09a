"""What a forward run of a scene produced, whichever path ran it (mm, s)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class SimulationResult:
    """What a run produced.

    Attributes
    ----------
    times_s
        Frame times (s), the first being t = 0 after settling.
    tissue_mm
        ``(frames, n_tissue, 3)`` tissue particle positions (mm, tank frame).
    tissue_volume_mm3
        Rest volume of each tissue particle (mm³), for :func:`~hifumotion.particles.section.section`.
    bar_centre_mm
        ``(frames, 3)`` bar centre of mass (mm), NaN without a bar.
    spacing_mm
        Particle spacing (mm).
    steps, facts
        Number of solver steps after settling; the scene's facts (counts, masses).
    """

    times_s: np.ndarray
    tissue_mm: np.ndarray
    tissue_volume_mm3: np.ndarray
    bar_centre_mm: np.ndarray
    spacing_mm: float
    steps: int
    facts: dict = field(default_factory=dict)
    system: object | None = None   # the particle path's ParticleSystem at the end of the run


__all__ = ["SimulationResult"]
