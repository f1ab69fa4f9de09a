"""Corotational kinematics of the voxel mesh: its elements' rotations taken out of their strain (SI).

The fast path's elasticity (:mod:`.hexahedra`) is small-strain: ``f = K u``. A voxel that
turns rigidly by an angle θ then carries a strain of order 1 − cos θ and a stress it should
not (a sample turned by 20° is stressed as if stretched by 6 %). The paper's Eq. 13 measures
strain by Green–Saint-Venant, which a rotation leaves at zero. The corotational formulation
(Felippa & Haugen, CMAME 2005; Müller & Gross, GI 2004, "warped stiffness"; SOFA's
``HexahedronFEMForceField``, method "polar") keeps the small-strain element but measures each
voxel's deformation in its own rotated frame:

    f_e = R_e K_e (R_eᵀ x_e − X_e),        x_e = X_e + u_e,

``R_e`` the rotation of the polar decomposition ``F = R U`` of the deformation gradient at the
voxel's centre. A rigid motion ``x = Q X + c`` gives ``R = Q`` and no force; ``R = I`` gives
back ``K u``. Expanded, ``f_e = R_e K_e R_eᵀ u_e + R_e K_e (R_eᵀ − I) X_e``: a rotated
stiffness and a load, which is how the backward-Euler step takes it (:mod:`.integrate`), the
rotations taken at the step's predictor and again by its rounds while the solution turns on
(a Picard iteration inside the step, :meth:`Corotation.moved`). The
viscosity's matrix turns with its voxel too, and its shear rate is read in the voxel's frame.
The material law stays linear in the rotated frame: large rotations are exact, large
stretches are not (docs/decisions.md, "Large deformations on the fast path").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from hifumotion.creep.hexahedra import deformation_gradient


@njit(cache=True)
def polar_rotation(f, out):
    """out = R of F = R U: Newton's iteration X ← ½ (X + X⁻ᵀ) from F (Higham, SIAM J. Sci. Stat.
    Comput. 1986; quadratic, a few 3 × 3 inverses where an SVD costs a LAPACK call); an inverted
    or unconverged F by the SVD, with the nearest proper rotation if det F ≤ 0."""
    x = f.copy()
    det = (x[0, 0] * (x[1, 1] * x[2, 2] - x[1, 2] * x[2, 1]) - x[0, 1] * (x[1, 0] * x[2, 2] - x[1, 2] * x[2, 0])
           + x[0, 2] * (x[1, 0] * x[2, 1] - x[1, 1] * x[2, 0]))
    if det > 1e-12:
        cof = np.empty((3, 3))
        for _ in range(30):
            # X⁻ᵀ = cof(X) / det X
            cof[0, 0] = x[1, 1] * x[2, 2] - x[1, 2] * x[2, 1]
            cof[0, 1] = x[1, 2] * x[2, 0] - x[1, 0] * x[2, 2]
            cof[0, 2] = x[1, 0] * x[2, 1] - x[1, 1] * x[2, 0]
            cof[1, 0] = x[0, 2] * x[2, 1] - x[0, 1] * x[2, 2]
            cof[1, 1] = x[0, 0] * x[2, 2] - x[0, 2] * x[2, 0]
            cof[1, 2] = x[0, 1] * x[2, 0] - x[0, 0] * x[2, 1]
            cof[2, 0] = x[0, 1] * x[1, 2] - x[0, 2] * x[1, 1]
            cof[2, 1] = x[0, 2] * x[1, 0] - x[0, 0] * x[1, 2]
            cof[2, 2] = x[0, 0] * x[1, 1] - x[0, 1] * x[1, 0]
            det = x[0, 0] * cof[0, 0] + x[0, 1] * cof[0, 1] + x[0, 2] * cof[0, 2]
            if det <= 0.0:
                break
            change = 0.0
            for i in range(3):
                for j in range(3):
                    new = 0.5 * (x[i, j] + cof[i, j] / det)
                    change = max(change, abs(new - x[i, j]))
                    x[i, j] = new
            if change < 1e-14:
                out[:, :] = x
                return
    w, _, vt = np.linalg.svd(f)
    r = w @ vt
    if np.linalg.det(r) < 0.0:
        for i in range(3):
            w[i, 2] = -w[i, 2]
        r = w @ vt
    out[:, :] = r


@njit(cache=True, parallel=True)
def _rotations(u, elements, grads, grad_of, out):
    for e in prange(elements.shape[0]):
        f = np.empty((3, 3))
        deformation_gradient(u, elements[e], grads[grad_of[e]], f)
        polar_rotation(f, out[e])


@njit(cache=True)
def _scatter_rotated(emap, blocks, block_of, scale, rot, data):
    """data[emap[e]] += scale[e] · R_e blocks[block_of[e]] R_eᵀ, node block by node block
    (serial: elements share entries)."""
    tmp = np.empty((3, 3))
    for e in range(emap.shape[0]):
        s = scale[e]
        if s == 0.0:
            continue
        blk = blocks[block_of[e]]
        r = rot[e]
        for a in range(8):
            for b in range(8):
                # tmp = blk_ab R_eᵀ, then R_e tmp
                for i in range(3):
                    for j in range(3):
                        acc = 0.0
                        for k in range(3):
                            acc += blk[3 * a + i, 3 * b + k] * r[j, k]
                        tmp[i, j] = acc
                for i in range(3):
                    for j in range(3):
                        acc = 0.0
                        for k in range(3):
                            acc += r[i, k] * tmp[k, j]
                        data[emap[e, 3 * a + i, 3 * b + j]] += s * acc


@njit(cache=True)
def _rotation_loads(rest, elements, blocks, block_of, rot, out):
    """out[node] += R_e K_e (R_eᵀ − I) X_e, X_e the voxel's corners from its centroid."""
    x = np.empty((8, 3))
    y = np.empty(24)
    for e in range(elements.shape[0]):
        r = rot[e]
        c = np.zeros(3)
        for a in range(8):
            for i in range(3):
                x[a, i] = rest[elements[e, a], i]
                c[i] += x[a, i] / 8.0
        for a in range(8):
            for i in range(3):
                acc = 0.0
                for k in range(3):
                    acc += r[k, i] * (x[a, k] - c[k])     # (R_eᵀ X)_i
                y[3 * a + i] = acc - (x[a, i] - c[i])
        z = blocks[block_of[e]] @ y
        for a in range(8):
            n = elements[e, a]
            for i in range(3):
                acc = 0.0
                for k in range(3):
                    acc += r[i, k] * z[3 * a + k]
                out[n, i] += acc


@njit(cache=True)
def _rotated_rates(velocity, elements, blocks, block_of, rot, out):
    """√(2 dev ε̇ : dev ε̇) (1/s) at each voxel's centre of the velocity seen in its frame (R_eᵀ v)."""
    vloc = np.empty(24)
    for e in range(elements.shape[0]):
        r = rot[e]
        for a in range(8):
            n = elements[e, a]
            for i in range(3):
                vloc[3 * a + i] = r[0, i] * velocity[n, 0] + r[1, i] * velocity[n, 1] + r[2, i] * velocity[n, 2]
        rate = blocks[block_of[e]] @ vloc
        tr = (rate[0] + rate[1] + rate[2]) / 3.0
        d0, d1, d2 = rate[0] - tr, rate[1] - tr, rate[2] - tr
        dd = d0 * d0 + d1 * d1 + d2 * d2 + 0.5 * (rate[3] ** 2 + rate[4] ** 2 + rate[5] ** 2)
        out[e] = np.sqrt(2.0 * dd)


@dataclass(frozen=True)
class Rotated:
    """The elastic force linearised with the voxels' rotations ``rotations`` (voxels, 3, 3):
    ``f(u) = K_R u + loads`` (CSR data of K_R on the mesh's pattern, N/m; loads (n, 3), N)."""

    rotations: np.ndarray
    stiffness_data: np.ndarray
    loads: np.ndarray


class Corotation:
    """The rotated element matrices of a :class:`~.hexahedra.MeshMatrices` (module docstring).

    ``two_g`` and ``kappa`` (Pa) make each voxel's stiffness ``2G·dev + κ·vol`` once; the
    viscosity's blocks are per unit μ (Pa·s).
    """

    def __init__(self, matrices, rest_m: np.ndarray, two_g: float, kappa: float):
        m = matrices
        self.matrices = m
        self.rest_m = np.ascontiguousarray(rest_m, float)
        n_el = len(m.elements)
        # block 0 is the exact cube's; block 1 + j the j-th distorted voxel's own
        self.block_of = np.zeros(n_el, np.int64)
        self.block_of[m.distorted] = 1 + np.arange(len(m.distorted))
        self.stiffness = np.ascontiguousarray(np.concatenate(
            [(two_g * m.cube.deviatoric + kappa * m.cube.volumetric)[None], two_g * m.dev + kappa * m.vol]))
        self.viscous = np.ascontiguousarray(np.concatenate([m.cube.viscous[None], m.visc]))
        self.centre_b = np.ascontiguousarray(np.concatenate([m.cube.centre_b[None], m.b0]))
        # ∂N_a/∂X at the centre (1/m): B's normal rows hold it
        b = self.centre_b
        self.gradients = np.ascontiguousarray(np.stack(
            [b[:, 0, 0::3], b[:, 1, 1::3], b[:, 2, 2::3]], axis=-1))   # (blocks, 8, 3)

    def rotations(self, u_m: np.ndarray) -> np.ndarray:
        """``(voxels, 3, 3)``: each voxel's rotation R_e (polar decomposition of F at its centre)
        for the node displacements ``u_m`` ``(n, 3)``."""
        out = np.empty((len(self.matrices.elements), 3, 3))
        _rotations(np.ascontiguousarray(u_m, float), self.matrices.elements, self.gradients, self.block_of, out)
        return out

    def _assembled(self, blocks: np.ndarray, scale: np.ndarray, rot: np.ndarray) -> np.ndarray:
        asm = self.matrices.assembly
        data = np.zeros(len(asm.indices))
        _scatter_rotated(asm.emap, blocks, self.block_of, np.ascontiguousarray(scale, float), rot, data)
        return data

    def stiffness_data(self, rot: np.ndarray) -> np.ndarray:
        """CSR data (on the mesh's pattern) of ``Σ_e R_e K_e R_eᵀ`` (N/m)."""
        return self._assembled(self.stiffness, np.ones(len(rot)), rot)

    def viscous_data(self, mu_pa_s: np.ndarray, state: Rotated) -> np.ndarray:
        """CSR data of ``Σ_e μ_e R_e C_e R_eᵀ`` (N·s/m), R_e ``state``'s rotations."""
        rot = state.rotations
        return self._assembled(self.viscous, np.broadcast_to(np.asarray(mu_pa_s, float), (len(rot),)), rot)

    def loads(self, rot: np.ndarray) -> np.ndarray:
        """``(n, 3)`` ``Σ_e R_e K_e (R_eᵀ − I) X_e`` (N): the elastic force is ``K_R u`` plus this."""
        out = np.zeros_like(self.rest_m)
        _rotation_loads(self.rest_m, self.matrices.elements, self.stiffness, self.block_of, rot, out)
        return out

    def forces(self, u_m: np.ndarray) -> np.ndarray:
        """``(n, 3)`` the corotational elastic force ``Σ_e R_e K_e (R_eᵀ x_e − X_e)`` (N) at ``u_m``,
        the rotations taken from ``u_m`` itself."""
        import scipy.sparse as sp

        rot = self.rotations(u_m)
        asm = self.matrices.assembly
        k = sp.csr_matrix((self.stiffness_data(rot), asm.indices, asm.indptr), shape=(asm.size, asm.size))
        return (k @ np.asarray(u_m, float).ravel()).reshape(-1, 3) + self.loads(rot)

    def linearised(self, u_m: np.ndarray, rot: np.ndarray | None = None) -> Rotated:
        """The force's K_R and loads with the rotations at ``u_m`` (or ``rot``, taken there)."""
        rot = self.rotations(u_m) if rot is None else rot
        return Rotated(rot, self.stiffness_data(rot), self.loads(rot))

    def moved(self, state: Rotated, u_m: np.ndarray, tolerance_m: float) -> Rotated | None:
        """The rotations at ``u_m`` if a voxel's differs from ``state``'s by more than ``tolerance_m``
        over the voxel's side (radians: its corners then move less than ``tolerance_m``), else None."""
        rot = self.rotations(u_m)
        if np.abs(rot - state.rotations).max() <= tolerance_m / self.matrices.cube.side_m:
            return None
        return self.linearised(u_m, rot)

    def rates(self, velocity_m_s: np.ndarray, u_m: np.ndarray) -> np.ndarray:
        """Equivalent shear rate (1/s) of every voxel, its velocity read in its own frame at ``u_m``."""
        rot = self.rotations(u_m)
        out = np.empty(len(rot))
        _rotated_rates(np.ascontiguousarray(velocity_m_s, float), self.matrices.elements, self.centre_b,
                       self.block_of, rot, out)
        return out


__all__ = ["Corotation", "Rotated"]
