"""Eq. 16's rheological viscosity law, in one place for every solver.

The paper's tissue resists shearing with a viscosity that depends on how fast it is sheared:

    μ(γ̇) = β₁ γ̇^β₂        (Pa·s; β₁ in Pa·s^(1+β₂), β₂ dimensionless, γ̇ in 1/s).

Two regularisations make it usable in a solver, and every solver here applies the same ones:

- the shear rate is floored at :data:`RATE_FLOOR_PER_S` — at rest γ̇ → 0 and β₂ < 1 would
  leave a tissue with no viscosity (β₂ > 0) or an infinite one (β₂ < 0);
- μ is capped at :data:`MU_MAX_PA_S`, where a near pair of particles (Eq. 12's |r_ij|² in the
  denominator) would blow the rate up.

How the shear rate γ̇ is measured belongs to each discretisation — a pair of particles
(:mod:`hifumotion.particles.viscosity`), a voxel (:mod:`hifumotion.creep`), the finite-element
truth's quadrature points (:mod:`hifumotion.reference.creep_fe`) — but the law from the rate to
μ is this module's :func:`viscosity_pa_s`: NumPy on arrays of any shape, and the same source
compiled by Numba inside the particle kernels (``njit(viscosity_pa_s)``). The module imports
no compiler, so a configuration's defaults can be read from it without one.
"""

from __future__ import annotations

import numpy as np

#: Floor of the shear rate in μ (1/s): a regularisation, not fitted. 0.02 1/s is a strain of
#: 2 % over a second, below the creep rates of a push (docs/decisions.md, "One protocol for the three integrators").
RATE_FLOOR_PER_S = 0.02

#: Cap of μ (Pa·s).
MU_MAX_PA_S = 1e7


def viscosity_pa_s(rate_per_s, beta1, beta2, rate_floor_per_s=RATE_FLOOR_PER_S, mu_max_pa_s=MU_MAX_PA_S):
    """Eq. 16's μ = β₁ max(γ̇, floor)^β₂ (Pa·s), capped at ``mu_max_pa_s``, at the shear rates
    γ̇ ``rate_per_s`` (1/s; a number or an array of any shape)."""
    return np.minimum(beta1 * np.maximum(rate_per_s, rate_floor_per_s) ** beta2, mu_max_pa_s)


__all__ = ["MU_MAX_PA_S", "RATE_FLOOR_PER_S", "viscosity_pa_s"]
