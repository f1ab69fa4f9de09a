"""Eq. 16's viscosity on a sample of voxels: energy-conserving sampling and weighting (ECSW).

The reduced model's viscous matrix ``C_r(μ) = Σ_e μ_e B_e`` (``B_e = V_eᵀ C_e V_e``, one
r × r block per voxel, μ_e Eq. 16's at the voxel's shear rate) is a sum over every voxel,
and each step also needs every voxel's rate: at the paper's 4,399 particles these were the
largest part of a reduced step (docs/decisions.md). ECSW (Farhat, Avery, Chapman & Cortial,
IJNME 2014; the hyper-reduction of SOFA's ModelOrderReduction) replaces the sum by a few
voxels with non-negative weights,

    C_r(μ) q̇ ≈ Σ_{e ∈ S} w_e μ_e B_e q̇,

the weights chosen so that the reduced viscous forces of the snapshots' own motion — at
their rates, for Eq. 16's law at β2 and two neighbours (β1 only scales μ) — are kept to
``tolerance`` of their size. Non-negative weights keep C_r positive semi-definite, so the
viscosity still only dissipates. The weights come from a greedy non-negative least squares
(columns added by the largest correlation with the residual, Lawson & Hanson's NNLS on those),
stopped at the tolerance: the sparse solution, not the exact one (which would use as many
voxels as there are equations).

:func:`shear_rates` gives each voxel's equivalent shear rate from the reduced velocity
directly (its centre's strain rate per unit q̇ made once): the same rate as
:meth:`~hifumotion.creep.hexahedra.MeshMatrices.rates`, without the node velocities.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hifumotion.creep.integrate import CreepMaterial


def rate_modes(matrices, node_modes_m: np.ndarray, voxels: np.ndarray) -> np.ndarray:
    """``(len(voxels), 6, r)``: each voxel's centre strain rate (engineering shear) per unit q̇."""
    r = node_modes_m.shape[1]
    elements = matrices.elements[voxels]
    dofs = (3 * elements[:, :, None] + np.arange(3)).reshape(len(voxels), 24)
    b0 = np.broadcast_to(matrices.cube.centre_b, (len(voxels), 6, 24)).copy()
    own = matrices.own_blocks(voxels)
    b0[own >= 0] = matrices.b0[own[own >= 0]]
    return np.ascontiguousarray(np.matmul(b0, node_modes_m[dofs].reshape(len(voxels), 24, r)))


def shear_rates(modes: np.ndarray, qdot: np.ndarray) -> np.ndarray:
    """Equivalent shear rate √(2 dev ε̇ : dev ε̇) (1/s) of each voxel of :func:`rate_modes` at ``qdot``."""
    e = modes @ qdot if qdot.ndim == 1 else np.einsum("esr,jr->jes", modes, qdot)
    normal = e[..., :3]
    dev = normal - normal.mean(axis=-1, keepdims=True)
    return np.sqrt(2.0 * (np.sum(dev ** 2, axis=-1) + 0.5 * np.sum(e[..., 3:] ** 2, axis=-1)))


@dataclass(frozen=True)
class SampledViscosity:
    """ECSW's voxels and their weights (all voxels with weight 1: no hyper-reduction)."""

    voxels: np.ndarray
    weights: np.ndarray
    residual: float          # the fit's relative residual on its training forces

    @property
    def size(self) -> int:
        return len(self.voxels)


def ecsw(blocks: np.ndarray, modes: np.ndarray, rates_q: np.ndarray, material: CreepMaterial,
         tolerance: float, max_voxels: int | None = None) -> SampledViscosity:
    """The sampled voxels and weights of ``blocks`` ``(voxels, r, r)`` (B_e per unit μ), their
    :func:`rate_modes` ``modes``, for the training velocities ``rates_q`` ``(J, r)`` under Eq. 16
    with ``material``'s law at its β2 and β2 ± 0.2 (module docstring)."""
    n = len(blocks)
    if len(rates_q) == 0 or n == 0:
        return SampledViscosity(np.arange(n), np.ones(n), 0.0)
    columns = []
    for beta2 in sorted({material.beta2, max(material.beta2 - 0.2, 0.05), min(material.beta2 + 0.2, 0.95)}):
        law = CreepMaterial(material.youngs_modulus_pa, material.poisson_ratio, 1.0, beta2,
                            rate_floor_per_s=material.rate_floor_per_s, mu_max_pa_s=material.mu_max_pa_s / material.beta1
                            if material.beta1 > 0 else material.mu_max_pa_s)
        mu = law.viscosity(shear_rates(modes, rates_q))                   # (J, voxels)
        forces = np.einsum("eab,jb->jea", blocks, rates_q) * mu[:, :, None]  # (J, voxels, r)
        total = forces.sum(axis=1)                                         # (J, r)
        size = np.linalg.norm(total, axis=1)
        keep = size > 1e-12 * max(size.max(), 1e-300)
        # each training force weighs the same: relative to its own size
        columns.append((forces[keep] / size[keep, None, None]).transpose(0, 2, 1).reshape(-1, n))
    a = np.vstack(columns)                                                 # (equations, voxels)
    active, weights, residual = greedy_weights(a, tolerance, max_voxels)
    return SampledViscosity(active, weights, residual)


def greedy_weights(a: np.ndarray, tolerance: float, max_voxels: int | None = None
                   ) -> tuple[np.ndarray, np.ndarray, float]:
    """ECSW's voxels and non-negative weights for the equations ``a`` ``(equations, voxels)``,
    whose right-hand side is every voxel at weight 1 (``a.sum(axis=1)``): a greedy NNLS (module
    docstring) stopped when the residual is below ``tolerance`` of the right-hand side or at
    ``max_voxels``. Returns (sorted voxels, their weights, the relative residual); every voxel at
    weight 1 (residual 0) if none was picked."""
    from scipy.optimize import nnls

    n = a.shape[1]
    b = a.sum(axis=1)
    target = tolerance * np.linalg.norm(b)
    limit = max_voxels or n
    active: list[int] = []
    residual = b.copy()
    weights = np.zeros(0)
    while np.linalg.norm(residual) > target and len(active) < limit:
        score = a.T @ residual
        score[active] = -np.inf
        # a few columns a round (the most correlated): far fewer NNLS solves for the same fit
        best = np.argsort(score)[-max(1, min(8, limit - len(active))):]
        best = [int(e) for e in best if score[e] > 0]
        if not best:
            break
        active += best
        weights, _ = nnls(a[:, active], b, maxiter=50 * len(active))
        kept = weights > 0
        active = [e for e, k in zip(active, kept) if k]
        weights = weights[kept]
        residual = b - a[:, active] @ weights
    if not active:
        return np.arange(n), np.ones(n), 0.0
    order = np.argsort(active)
    return (np.asarray(active)[order], weights[order],
            float(np.linalg.norm(residual) / max(np.linalg.norm(b), 1e-300)))

__all__ = ["SampledViscosity", "ecsw", "greedy_weights", "rate_modes", "shear_rates"]
