"""Finite-strain elasticity of the voxel mesh: a nearly incompressible neo-Hooke, total Lagrangian (SI).

The paper's Eq. 13 measures strain by Green–Saint-Venant; the twins' truth is a neo-Hookean
solid (:mod:`hifumotion.reference.finite_strain`). Under a bar driven 30–40 % into the
tissue, linear elasticity — small-strain or corotated (:mod:`.corotation`) — is softer in
compression than that law, and the section's shape shows it (docs/decisions.md,
"Large deformations on the fast path"). Here each voxel stores the strain energy

    W = μ/2 (J^(−2/3) I₁ − 3) + κ/2 (J − 1)²,        I₁ = tr FᵀF,  J = det F,

(FElupe's ``NeoHooke``, the truth's law), integrated as the small-strain element is
(:mod:`.hexahedra`): its isochoric part at the 2 × 2 × 2 Gauss points, its volumetric part at
the centre (selective reduced integration, Hughes 1980), so that at F = I its tangent *is*
the small-strain ``2G·dev + κ·vol`` — today's model is its limit. The first Piola–Kirchhoff
stress and its tangent ``A = ∂P/∂F`` are

    P = μ J^(−2/3) (F − I₁/3 F⁻ᵀ) + κ (J − 1) J F⁻ᵀ,
    A_iJkL = μ J^(−2/3) [δ_ik δ_JL − ⅔ F_iJ F⁻¹_Lk − ⅔ F⁻¹_Ji F_kL
                          + ²⁄₉ I₁ F⁻¹_Ji F⁻¹_Lk + ⅓ I₁ F⁻¹_Li F⁻¹_Jk]
             + κ (2J − 1) J F⁻¹_Ji F⁻¹_Lk − κ (J − 1) J F⁻¹_Jk F⁻¹_Li,

each voxel's 24 × 24 tangent made positive semi-definite where it is not by clamping its
negative eigenvalues at zero — projected Newton (Teran, Sifakis, Irving & Fedkiw, SCA 2005):
under compression the initial stress can make it indefinite, and the step's factorisation needs
a positive system; the forces stay exact, so a converged step is the exact one. The step
(:mod:`.integrate`) takes the elastic force as its linearisation at a point u*,
``f(u) ≈ K_T(u*) u + (f(u*) − K_T(u*) u*)``: a tangent stiffness and a load, re-linearised by
the rounds while the solution moves from u* (Newton's iteration inside the step, beside the
contacts' and the friction's). Eq. 16's viscosity stays the small-strain Kelvin–Voigt term on
the rate (its forces are small beside the elastic ones at these rates).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from hifumotion.creep.hexahedra import _XI, _b_at, deformation_gradient, strain_matrix


@njit(cache=True, parallel=True)
def _element_tangents(u, elements, grads, weights, block_of, mu, kappa, project, k_out, f_out):
    """Each voxel's 24 × 24 tangent and 24 internal forces at the node displacements ``u``;
    ``grads[b, p]`` (8 × 3, 1/m) and ``weights[b, p]`` (m³) the reference gradients and
    weights of block b's nine points (the eight Gauss points, then the centre)."""
    for e in prange(elements.shape[0]):
        blk = block_of[e]
        ke = np.zeros((24, 24))
        fe = np.zeros(24)
        f = np.empty((3, 3))
        a4 = np.empty((3, 3, 3, 3))
        h = np.empty((3, 3, 8, 3))
        for p in range(9):
            g = grads[blk, p]
            w = weights[blk, p]
            deformation_gradient(u, elements[e], g, f)
            jac = np.linalg.det(f)
            if jac <= 0.0:
                jac = 1e-12   # an inverted point: kept finite, the step controller rejects the step
            finv = np.linalg.inv(f)
            pk = np.empty((3, 3))
            if p < 8:
                i1 = 0.0
                for i in range(3):
                    for j in range(3):
                        i1 += f[i, j] * f[i, j]
                c = mu * jac ** (-2.0 / 3.0)
                for i in range(3):
                    for j in range(3):
                        pk[i, j] = c * (f[i, j] - i1 / 3.0 * finv[j, i])
                for i in range(3):
                    for j in range(3):
                        for k in range(3):
                            for m in range(3):
                                v = (-2.0 / 3.0 * f[i, j] * finv[m, k] - 2.0 / 3.0 * finv[j, i] * f[k, m]
                                     + 2.0 / 9.0 * i1 * finv[j, i] * finv[m, k] + i1 / 3.0 * finv[m, i] * finv[j, k])
                                if i == k and j == m:
                                    v += 1.0
                                a4[i, j, k, m] = c * v
            else:
                s1 = kappa * (jac - 1.0) * jac
                s2 = kappa * (2.0 * jac - 1.0) * jac
                for i in range(3):
                    for j in range(3):
                        pk[i, j] = s1 * finv[j, i]
                for i in range(3):
                    for j in range(3):
                        for k in range(3):
                            for m in range(3):
                                a4[i, j, k, m] = s2 * finv[j, i] * finv[m, k] - s1 * finv[j, k] * finv[m, i]
            for a in range(8):
                for i in range(3):
                    acc = 0.0
                    for j in range(3):
                        acc += pk[i, j] * g[a, j]
                    fe[3 * a + i] += w * acc
            # H[i, k, a, L] = Σ_J A_iJkL g_aJ, then K[(a,i),(b,k)] += w Σ_L H[i, k, a, L] g_bL
            for i in range(3):
                for k in range(3):
                    for a in range(8):
                        for m in range(3):
                            h[i, k, a, m] = (a4[i, 0, k, m] * g[a, 0] + a4[i, 1, k, m] * g[a, 1]
                                             + a4[i, 2, k, m] * g[a, 2])
            for a in range(8):
                for i in range(3):
                    for b in range(8):
                        for k in range(3):
                            ke[3 * a + i, 3 * b + k] += w * (h[i, k, a, 0] * g[b, 0] + h[i, k, a, 1] * g[b, 1]
                                                             + h[i, k, a, 2] * g[b, 2])
        # the voxel's tangent made positive semi-definite (projected Newton): under compression the
        # initial stress can make it indefinite, and the step's factorisation needs a positive
        # system; where it is already, it is kept as it is (its rigid modes' zeros aside)
        ke = 0.5 * (ke + ke.T)
        lam, vec = np.linalg.eigh(ke)
        if project and lam[0] < -1e-10 * lam[23]:
            for r in range(24):
                if lam[r] < 0.0:
                    lam[r] = 0.0
            ke = (vec * lam) @ vec.T
        k_out[e] = ke
        f_out[e] = fe


@njit(cache=True)
def _scatter_elements(emap, elements, k_el, f_el, data, forces):
    for e in range(emap.shape[0]):
        for p in range(24):
            forces[elements[e, p // 3], p % 3] += f_el[e, p]
            for q in range(24):
                data[emap[e, p, q]] += k_el[e, p, q]


@njit(cache=True)
def _distorted_points(x, elements, which, grads, weights):
    g = 1.0 / math.sqrt(3.0)
    b = np.empty((6, 24))
    x_e = np.empty((8, 3))
    for m in range(which.shape[0]):
        e = which[m]
        for a in range(8):
            for c in range(3):
                x_e[a, c] = x[elements[e, a], c]
        for p in range(9):
            if p < 8:
                det = _b_at(x_e, _XI[p, 0] * g, _XI[p, 1] * g, _XI[p, 2] * g, b)
                weights[m, p] = det
            else:
                det = _b_at(x_e, 0.0, 0.0, 0.0, b)
                weights[m, p] = 8.0 * det
            for a in range(8):
                grads[m, p, a, 0] = b[0, 3 * a]
                grads[m, p, a, 1] = b[1, 3 * a + 1]
                grads[m, p, a, 2] = b[2, 3 * a + 2]


@dataclass(frozen=True)
class Linearised:
    """The elastic force linearised at ``u_m``: ``f(u) ≈ K_T u + loads`` (CSR data of K_T on the
    mesh's pattern, N/m; ``loads`` (n, 3), N; ``forces`` the force f(u_m) itself, N)."""

    u_m: np.ndarray
    stiffness_data: np.ndarray
    forces: np.ndarray
    loads: np.ndarray


class NeoHooke:
    """The neo-Hookean elasticity of a :class:`~.hexahedra.MeshMatrices`' voxels (module docstring);
    ``shear_pa`` μ (= G) and ``bulk_pa`` κ (= λ + 2G/3)."""

    def __init__(self, matrices, rest_m: np.ndarray, shear_pa: float, bulk_pa: float):
        m = matrices
        self.matrices = m
        self.mu, self.kappa = float(shear_pa), float(bulk_pa)
        n_el = len(m.elements)
        self.block_of = np.zeros(n_el, np.int64)
        self.block_of[m.distorted] = 1 + np.arange(len(m.distorted))
        grads = np.zeros((1 + len(m.distorted), 9, 8, 3))
        weights = np.zeros((1 + len(m.distorted), 9))
        side = m.cube.side_m
        for p in range(9):
            point = _XI[p] / math.sqrt(3.0) if p < 8 else np.zeros(3)
            b = strain_matrix(point, side)
            grads[0, p] = np.stack([b[0, 0::3], b[1, 1::3], b[2, 2::3]], axis=-1)
            weights[0, p] = (side / 2.0) ** 3 * (8.0 if p == 8 else 1.0)
        if len(m.distorted):
            _distorted_points(np.ascontiguousarray(rest_m, float), m.elements, np.ascontiguousarray(m.distorted),
                              grads[1:], weights[1:])
        self.grads, self.weights = grads, weights

    def linearised(self, u_m: np.ndarray, project: bool = True) -> Linearised:
        """The tangent and the forces at the node displacements ``u_m`` ``(n, 3)`` (m); ``project``:
        each voxel's tangent made positive semi-definite (module docstring), else the exact one."""
        u = np.ascontiguousarray(u_m, float)
        n_el = len(self.matrices.elements)
        k_el = np.empty((n_el, 24, 24))
        f_el = np.empty((n_el, 24))
        _element_tangents(u, self.matrices.elements, self.grads, self.weights, self.block_of, self.mu,
                          self.kappa, bool(project), k_el, f_el)
        asm = self.matrices.assembly
        data = np.zeros(len(asm.indices))
        forces = np.zeros_like(u)
        _scatter_elements(asm.emap, self.matrices.elements, k_el, f_el, data, forces)
        import scipy.sparse as sp

        k = sp.csr_matrix((data, asm.indices, asm.indptr), shape=(asm.size, asm.size))
        loads = forces - (k @ u.ravel()).reshape(-1, 3)
        return Linearised(u.copy(), data, forces, loads)

    def moved(self, state: Linearised, u_m: np.ndarray, tolerance_m: float) -> Linearised | None:
        """A new linearisation at ``u_m`` if a node moved more than ``tolerance_m`` from ``state``'s
        point, else None (Newton's iteration inside a step, :mod:`.integrate`)."""
        if np.abs(np.asarray(u_m) - state.u_m).max() <= tolerance_m:
            return None
        return self.linearised(u_m)

    def viscous_data(self, mu_pa_s, state: Linearised) -> None:
        """None: the viscosity stays the small-strain Kelvin–Voigt term (module docstring)."""
        return None

    def rates(self, velocity_m_s: np.ndarray, u_m: np.ndarray) -> np.ndarray:
        """Eq. 16's equivalent shear rate (1/s) per voxel: the small-strain one."""
        return self.matrices.rates(velocity_m_s)

    def forces(self, u_m: np.ndarray) -> np.ndarray:
        """``(n, 3)`` the elastic force (N) at ``u_m``: ∂/∂u of the voxels' stored energy."""
        return self.linearised(u_m).forces

    def energy(self, u_m: np.ndarray) -> float:
        """The stored energy (J) at ``u_m`` (tests: the forces are its gradient)."""
        u = np.asarray(u_m, float)
        elements = self.matrices.elements
        total = 0.0
        for p in range(9):
            g = self.grads[self.block_of, p]                                   # (E, 8, 3)
            f = np.eye(3) + np.einsum("eai,eaj->eij", u[elements], g)
            jac = np.linalg.det(f)
            if p < 8:
                i1 = np.einsum("eij,eij->e", f, f)
                w = self.mu / 2.0 * (jac ** (-2.0 / 3.0) * i1 - 3.0)
            else:
                w = self.kappa / 2.0 * (jac - 1.0) ** 2
            total += float(np.sum(self.weights[self.block_of, p] * w))
        return total


__all__ = ["NeoHooke", "Linearised"]
