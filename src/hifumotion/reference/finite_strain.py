"""The tissue's law at finite strain, for a truth that the small-strain model cannot share.

A push large enough to matter strains the tissue under the bar beyond 30 %, where
the small-strain truth (:mod:`.creep_fe`) and the fitted model are wrong in the same way. The
paper's own elasticity (Eq. 13) is finite-strain. This module holds the finite-strain form of
the tissue's two laws, for FElupe (Voigt, Zenodo 2021; nonlinear solids, rigid contact):

* **Elasticity**: a nearly incompressible neo-Hookean solid, shear modulus G = E / (2(1 + ν)),
  bulk modulus K = E / (3(1 − 2ν)) (the small-strain E, ν it reduces to at small strain),
  on FElupe's mixed three-field form (:class:`felupe.SolidBodyNearlyIncompressible`), which
  does not lock as ν → 0.5.
* **Viscosity** (Eq. 12 and 16 as a continuum, Kelvin–Voigt, as the small-strain truth and
  the fitted model take it): the viscous Cauchy stress σ_v = 2 μ(γ̇) **d**, **d** the rate of
  deformation, γ̇ = √(2 **d** : **d**), μ = β₁ max(γ̇, floor)^β₂ — the law of
  :mod:`hifumotion.rheology`, whose μ cap (10⁷ Pa·s, for near particle pairs) no continuum
  reaches and is left out. In a backward-Euler step of length Δt the stress derives from an
  *incremental potential* (Ortiz & Stainier, CMAME 1999): W_v = Δt φ(γ̇) with
  φ(γ̇) = ∫₀^γ̇ μ(s) s ds, so ∂W_v/∂**d** = Δt μ γ̇ ∂γ̇/∂**d** = Δt 2 μ **d** exactly, for any β₂.
  (γ̇ is the whole rate's, not its deviator's: a nearly incompressible tissue keeps tr **d**
  near zero, so the two differ little — but μ at the deviatoric rate times the volumetric rate
  is no potential's derivative that stays smooth where the deviatoric rate vanishes, and its
  tangent was 23 % off its own force's derivative once a driven bar stopped, docs/decisions.md.)
  The rate is measured objectively from the right Cauchy–Green tensors of the step's end
  and start: Ė = (C − Cₙ) / (2Δt), and **d** = F⁻ᵀ Ė F⁻¹ has the invariants
  tr **d** = tr(Ė C⁻¹), **d** : **d** = tr(Ė C⁻¹ Ė C⁻¹), which need C only. Cₙ is the
  material's state (six components), updated when a step converges.

Units inside FElupe: mm, N, MPa (N/mm²), s; β₁ in MPa·s^β₂ (Pa·s^(1+β₂) × 10⁻⁶).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hifumotion.errors import InputError
from hifumotion.rheology import RATE_FLOOR_PER_S

#: Pa → MPa (FElupe's stress unit with mm and N).
PA_TO_MPA = 1e-6


def viscous_increment_potential(C, statevars, beta1_mpa_s_pow, beta2, rate_floor_per_s, dtime_s):
    """Δt φ(γ̇) (MPa = N mm / mm³) of one backward-Euler step ending at the right Cauchy–Green
    tensor ``C`` (a :mod:`tensortrax` tensor), from the state ``statevars`` (the upper triangle
    of Cₙ, the step's start), and the new state (module docstring)."""
    import tensortrax.math as tm
    from tensortrax.math.linalg import inv
    from tensortrax.math.special import from_triu_1d, triu_1d

    c_start = from_triu_1d(statevars[:6], like=C)
    rate = (C - c_start) / (2.0 * dtime_s)                 # Ė (1/s)
    a = rate @ inv(C)                                      # Ė C⁻¹: d's invariants
    # γ̇² = 2 d : d ≥ 0 (up to round-off). No max(·, 0) here: at rest (C = Cₙ, the first
    # iteration of every step) the max's derivative takes the branch 0 and the tangent loses
    # the viscosity — Newton's line search then finds no decrease (docs/decisions.md, issue
    # 41). A round-off negative only enters the floor's quadratic branch, where it is harmless.
    gamma2 = 2.0 * tm.trace(a @ a)
    f2 = rate_floor_per_s ** 2
    # φ(γ̇) = ∫₀^γ̇ μ(s) s ds, written in γ̇² (no square root, whose second derivative at rest
    # is infinite); the branch above the floor sees γ̇² ≥ floor² only, for the same reason
    below = 0.5 * beta1_mpa_s_pow * rate_floor_per_s ** beta2 * gamma2
    p = 0.5 * (beta2 + 2.0)
    above = (0.5 * beta1_mpa_s_pow * rate_floor_per_s ** (beta2 + 2.0)
             + beta1_mpa_s_pow * (tm.maximum(gamma2, f2) ** p - f2 ** p) / (beta2 + 2.0))
    phi = tm.if_else(gamma2 <= f2, below, above)
    return dtime_s * phi, triu_1d(C)


@dataclass(frozen=True)
class TissueLaw:
    """The tissue (SI, as :mod:`hifumotion.rheology` and Table 3 give it): E (Pa), ν, β₁
    (Pa·s^(1+β₂)), β₂ and the shear-rate floor (1/s)."""

    youngs_modulus_pa: float
    poisson_ratio: float
    beta1: float = 0.0
    beta2: float = 0.5
    rate_floor_per_s: float = RATE_FLOOR_PER_S

    def __post_init__(self):
        if not self.youngs_modulus_pa > 0:
            raise InputError(f"must be > 0 Pa, got {self.youngs_modulus_pa}", "youngs_modulus_pa")
        if not 0.0 <= self.poisson_ratio < 0.5:
            raise InputError(f"must be in [0, 0.5), got {self.poisson_ratio}", "poisson_ratio")
        if not self.beta1 >= 0 or not self.rate_floor_per_s > 0:
            raise InputError("β1 must be ≥ 0 and the rate floor > 0", "beta1")

    @property
    def shear_modulus_mpa(self) -> float:
        return self.youngs_modulus_pa * PA_TO_MPA / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def bulk_modulus_mpa(self) -> float:
        return self.youngs_modulus_pa * PA_TO_MPA / (3.0 * (1.0 - 2.0 * self.poisson_ratio))

    def bodies(self, field, dtime_s: float):
        """FElupe's bodies of the law on ``field`` (mm): the elastic one, and the viscous one
        (``None`` when β₁ = 0) for steps of ``dtime_s``; its step length is
        ``viscous.umat.kwargs["dtime_s"]``."""
        import felupe as fem

        elastic = fem.SolidBodyNearlyIncompressible(fem.NeoHooke(mu=self.shear_modulus_mpa), field,
                                                    bulk=self.bulk_modulus_mpa)
        if self.beta1 <= 0:
            return elastic, None
        umat = fem.Hyperelastic(viscous_increment_potential, nstatevars=6,
                                beta1_mpa_s_pow=self.beta1 * PA_TO_MPA, beta2=self.beta2,
                                rate_floor_per_s=self.rate_floor_per_s, dtime_s=float(dtime_s))
        viscous = fem.SolidBody(umat, field, statevars=_identity_state(field))
        return elastic, viscous


def _identity_state(field):
    """The viscous body's initial state: Cₙ = I (the rest configuration) at every quadrature point."""
    region = field[0].region
    state = np.zeros((6, region.quadrature.npoints, region.mesh.ncells))
    state[[0, 3, 5]] = 1.0                # upper triangle of I: (11, 12, 13, 22, 23, 33)
    return state


__all__ = ["PA_TO_MPA", "TissueLaw", "viscous_increment_potential"]
