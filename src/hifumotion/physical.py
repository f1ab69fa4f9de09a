"""Physical constants and the materials' nominal values, once (SI).

The paper's fitted values (Table 3) are in :mod:`hifumotion.paper`; these are what the paper
takes as known: the water, gravity, the density of soft tissue.
"""

from __future__ import annotations

#: Density of soft tissue (kg/m³): the tissue of every model, truth and twin unless set.
TISSUE_DENSITY_KG_M3 = 1050.0
#: Rest density of the pool's water (kg/m³).
WATER_DENSITY_KG_M3 = 1000.0
#: Standard gravity (m/s²).
STANDARD_GRAVITY_M_S2 = 9.80665

__all__ = ["STANDARD_GRAVITY_M_S2", "TISSUE_DENSITY_KG_M3", "WATER_DENSITY_KG_M3"]
