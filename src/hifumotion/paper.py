"""The paper's numbers, once: Liao et al., Section 3.2 and Table 3.

Everything in the package that means "as the paper did" reads it from here, so a
default that departs from the paper does so visibly, in its own module.
"""

from __future__ import annotations

#: Table 3: the pushing force held by the bar (N).
FORCE_N = 0.25
#: Table 3: Young's modulus E of the tissue (Pa).
YOUNGS_MODULUS_PA = 13e3
#: Table 3: Poisson's ratio ν.
POISSON_RATIO = 0.47
#: Table 3: β1 of the rheological viscosity, Eq. 16 (Pa·s^(1+β2)).
BETA1 = 1.0
#: Table 3: β2 of the rheological viscosity, Eq. 16.
BETA2 = 0.5

#: Section 3.2: the particle counts of the fitted model — tissue, water, bar.
TISSUE_PARTICLES = 4399
WATER_PARTICLES = 3344
BAR_PARTICLES = 120

#: Section 3.2: a series of this many frames, ground truth every 10th from the 20th:
#: frames 20, 30, …, 100 train the model, 110, …, 190 validate it.
SERIES_FRAMES = 200
TRAINING_FRAMES = tuple(range(20, 101, 10))
VALIDATION_FRAMES = tuple(range(110, 191, 10))

__all__ = ["FORCE_N", "YOUNGS_MODULUS_PA", "POISSON_RATIO", "BETA1", "BETA2", "TISSUE_PARTICLES",
           "WATER_PARTICLES", "BAR_PARTICLES", "SERIES_FRAMES", "TRAINING_FRAMES", "VALIDATION_FRAMES"]
