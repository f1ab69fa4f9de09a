"""The forward models' numerical settings, as plain data (no solver imported).

:class:`CreepSettings` (the fast path, :mod:`.integrate`) and :class:`ReducedSettings` (its
reduced model, :mod:`hifumotion.reduced`) are reached from a run's configuration
(``[estimation.model.creep]``, ``[estimation.model.reduced]``) and ``--set``: they are
validated there by their annotations — a value's type, and the ranges the ``Annotated``
bounds give — and passed on to the solver as they are. Their defaults live here only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

from annotated_types import Ge, Gt, Le, Lt

Positive = Annotated[float, Gt(0)]
Fraction = Annotated[float, Gt(0), Lt(1)]
Count = Annotated[int, Ge(1)]


@dataclass
class CreepSettings:
    """Numerical settings of the fast path.

    Attributes
    ----------
    tolerance
        Local error of a step (backward Euler's ½ Δt |Δu̇|), in particle spacings.
    first_step_s, max_step_s
        The first step and the largest one (s); the first defaults to the output interval / 4.
    contact_tolerance
        A free node closer than this many spacings *behind* a surface is put in contact.
    max_rounds
        Rounds of the active-set rules and the friction's linearisation per step.
    cg_iterations, cg_rtol
        Conjugate-gradient budget before a fresh factorisation, and the relative residual of
        a step's solution.
    round_rtol
        The relative residual of a round's solution (the rounds only decide the contact set
        and the friction's linearisation; the last one is solved on to ``cg_rtol``).
    friction_rtol
        A step's rounds end when no contact changed and every contact's friction, at its
        new normal reaction, is the linearised one to this fraction of μ_f λ_n.
    stick_mm
        The elastic stick's reach ε (mm): a contact sticks up to this tangential
        displacement from its anchor and slides beyond it. 10 µm, a hundredth of a
        spacing (the FE truth's is 1 µm): the same motion to 0.5 µm of its error against
        the truth, a third fewer solves (docs/decisions.md).
    bar_edge_spacings
        The bar's rim rounded at this many spacings (when its ``edge_radius_m`` is not given):
        a voxel mesh cannot resolve a sharper edge, and a sharp one hooks a sliding sample
        (:mod:`.contact`, docs/decisions.md).
    newton_rounds
        Rounds that linearise the friction by its tangent (Newton); later ones take the
        secant, which always settles.
    solver
        ``"pardiso"``, ``"superlu"`` or None (the best installed).
    precision
        ``"mixed"``: the factorisation in single precision, its solutions refined by conjugate
        gradients to ``cg_rtol`` (:mod:`.linear`); ``"double"``: a double-precision factor.
    kinematics
        ``"small_strain"``: ``f = K u`` (a turned voxel is stressed); ``"corotational"``: each
        voxel's rotation taken out of its strain (:mod:`.corotation`), so that a sample may
        turn and slide far with no stress the turn made; ``"neo_hooke"``: finite strain, the
        truth's nearly incompressible neo-Hooke (:mod:`.neo_hooke`). All three agree at small
        strain. The reduced model takes small strain or corotational (:mod:`hifumotion.reduced.corotated_force`).
    """

    tolerance: Positive = 0.005
    first_step_s: Positive | None = None
    max_step_s: Positive = 1.0
    contact_tolerance: Annotated[float, Ge(0)] = 1e-4
    max_rounds: Count = 30
    cg_iterations: Count = 12
    cg_rtol: Fraction = 1e-9
    round_rtol: Fraction = 1e-6
    friction_rtol: Fraction = 1e-3
    stick_mm: Positive = 1e-2
    bar_edge_spacings: Annotated[float, Ge(0)] = 0.5
    newton_rounds: Annotated[int, Ge(0)] = 8
    solver: Literal["pardiso", "superlu"] | None = None
    precision: Literal["mixed", "double"] = "mixed"
    kinematics: Literal["small_strain", "corotational", "neo_hooke"] = "small_strain"


@dataclass
class ReducedSettings:
    """Numerical settings of the reduced model.

    Attributes
    ----------
    energy, max_modes
        What :func:`pod_basis` keeps.
    contact_reach
        Contact candidates: the surface nodes closer to a solid at rest than the snapshots'
        largest node motion plus this many spacings.
    contact_tolerance
        A candidate is in contact when its gap is below this many spacings.
    kept_on_solid
        A node on a plane or the bar's face at rest whose gap stayed within this many spacings
        in every snapshot is held there by the modes (:func:`~hifumotion.reduced.model.held_on_solids`; 1 %,
        the penetration the twins' physicality check allows); 0 holds none.
    friction
        Coulomb's friction on the candidates (:mod:`hifumotion.reduced.friction`); False leaves sliding
        free (the reduced model before it, kept to measure what friction buys).
    friction_touch
        A friction candidate presses while its gap is below this many spacings.
    friction_balance
        The floor's and the bar's face's normal reactions scaled to what the sample's balance
        gives each (the net weight, the bar's push; :meth:`~hifumotion.reduced.friction.ReducedFriction.balanced`):
        the candidates' own rows carried a tenth of it on a stuck slide. Off by default: measured
        mixed (docs/decisions.md, "A friction the reduced model is run at"). False takes the rows as they are.
    friction_rounds, friction_rtol
        A step re-linearises the friction at most this many times, until the law holds to
        ``friction_rtol`` of each node's μ_f λ_n.
    hyper_reduction, hyper_tolerance, hyper_samples
        Eq. 16's viscosity on ECSW's sampled voxels (:mod:`hifumotion.reduced.hyper`), fitted to this relative
        error on ``hyper_samples`` of the snapshots' velocities; False sums every voxel.
    corotation_tolerance, rotation_rounds
        A corotational mesh (``CreepSettings.kinematics``): its elastic force on ECSW's sampled
        voxels, fitted to this relative error on ``hyper_samples`` of the snapshots' states (0 sums
        every voxel; :mod:`hifumotion.reduced.corotated_force`); a step takes the rotations again at most
        ``rotation_rounds`` times while its solution turns on (the settled state: four times as many).
    tolerance, max_step_s, first_step_s
        The step controller's, as :class:`~.integrate.CreepSettings` (spacings, s).
    """

    energy: Fraction = 1.0 - 1e-8
    max_modes: Annotated[int, Ge(1), Le(1000)] = 40
    contact_reach: Annotated[float, Ge(0)] = 1.0
    contact_tolerance: Annotated[float, Ge(0)] = CreepSettings.contact_tolerance
    kept_on_solid: Annotated[float, Ge(0)] = 1e-2
    friction: bool = True
    friction_touch: Positive = 1e-2
    friction_balance: bool = False
    friction_rounds: Count = 4
    friction_rtol: Fraction = 1e-2
    hyper_reduction: bool = True
    hyper_tolerance: Fraction = 1e-3
    hyper_samples: Count = 8
    corotation_tolerance: Annotated[float, Ge(0), Lt(1)] = 1e-3
    rotation_rounds: Count = 8
    tolerance: Positive = CreepSettings.tolerance
    max_step_s: Positive = CreepSettings.max_step_s
    first_step_s: Positive | None = None


__all__ = ["CreepSettings", "ReducedSettings"]
