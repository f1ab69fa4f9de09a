"""The corotational elastic force in the reduced coordinates, on a sample of voxels (SI inside).

The reduced model (:mod:`.model`) of a small-strain mesh has a constant stiffness
``K_r = Vᵀ K V``, made once. With corotational kinematics (:mod:`hifumotion.creep.corotation`) each voxel's
force ``f_e = R_e K_e (R_eᵀ x_e − X_e)`` turns with the voxel, so the reduced force
``Vᵀ f(u₀ + V q)`` and its matrix ``Σ_e V_eᵀ R_e K_e R_eᵀ V_e`` change with q, and summing
them over every voxel would cost a full-model force a step. As for the viscosity
(:mod:`.hyper`), ECSW (Farhat et al., IJNME 2014) replaces the sum by a few voxels with
non-negative weights, chosen so that the reduced elastic forces of the snapshots' own
states — each voxel's deviatoric and volumetric parts apart, so that any E and ν are served
— are kept to a tolerance:

    f_r(q) ≈ Σ_{e ∈ S} w_e V_eᵀ R_e K_e (R_eᵀ x_e − X_e),
    K_R,r  ≈ Σ_{e ∈ S} w_e (R_eᵀ V_e)ᵀ K_e (R_eᵀ V_e),

``K_e = 2G K_dev,e + κ K_vol,e``. Non-negative weights keep K_R,r positive semi-definite.
The step takes the force linearised with the rotations at a point (the full model's
``K_R u + loads``; its geometric stiffness left out, as there) and the reduced step's rounds
take the rotations again while the solution turns on (:meth:`ReducedCorotation.moved`):
the full corotational model's Picard iteration, on the sample.

Eq. 16's viscosity turns too (:class:`TurnedViscosity`): its blocks ``R_e C_e R_eᵀ`` and its
shear rate read in the voxel's frame, as the full corotational model's. So does the elastic
force from which the friction's normal reactions are read (:class:`CandidateForces`).

Each voxel's r × r part of a turned matrix costs far more than its force, and under a push
most voxels barely turn from one step to the next: a part is kept while its voxel's rotation
stays within a tolerance of the one it was taken at (:class:`VoxelFrames`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from hifumotion.creep.corotation import polar_rotation
from hifumotion.reduced.hyper import greedy_weights


@dataclass(frozen=True)
class CorotatedForce:
    """The reduced elastic force at a point and its matrix.

    ``rotations`` ``(sample, 3, 3)`` the sample's rotations at ``at`` (m); ``force`` ``(r,)`` (N
    per unit q, the total from the rest state) with them; ``matrix`` ``(r, r)`` K_R,r (N/m per
    unit q²), each voxel's part taken at a rotation within the tolerance of its own there
    (:meth:`ReducedCorotation.at`)."""

    rotations: np.ndarray
    force: np.ndarray
    matrix: np.ndarray
    at: np.ndarray


class VoxelFrames:
    """The rotations of some voxels of a mesh at reduced coordinates q, and their modes turned
    into each voxel's frame.

    ``voxels`` of ``matrices``' mesh; ``node_modes_m`` ``(3n, r)``; ``settled_m`` ``(3n,)`` the
    displacement from rest at q = 0 (m)."""

    def __init__(self, matrices, node_modes_m: np.ndarray, settled_m: np.ndarray, voxels: np.ndarray):
        m = matrices
        self.voxels = np.asarray(voxels, np.int64)
        self.side_m = m.cube.side_m
        self.block_of = np.zeros(len(m.elements), np.int64)
        self.block_of[m.distorted] = 1 + np.arange(len(m.distorted))
        b = np.concatenate([m.cube.centre_b[None], m.b0])
        grads = np.stack([b[:, 0, 0::3], b[:, 1, 1::3], b[:, 2, 2::3]], axis=-1)   # ∂N_a/∂X at the centre
        dofs = (3 * m.elements[self.voxels][:, :, None] + np.arange(3)).reshape(len(self.voxels), 24)
        self.modes = np.ascontiguousarray(node_modes_m[dofs])                 # (voxels, 24, r)
        self.settled = np.ascontiguousarray(np.asarray(settled_m, float)[dofs])
        self.grads = np.ascontiguousarray(grads[self.block_of[self.voxels]])

    def elastic_parts(self, matrices, rest_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The voxels' K_dev and K_vol blocks ``(voxels, 24, 24)`` (per unit 2G, per unit κ) and
        their corners at rest from each one's centre ``(voxels, 24)`` (m), X_e of the force."""
        m = matrices
        of = self.block_of[self.voxels]
        corners = np.asarray(rest_m, float)[m.elements[self.voxels]]
        return (np.ascontiguousarray(np.concatenate([m.cube.deviatoric[None], m.dev])[of]),
                np.ascontiguousarray(np.concatenate([m.cube.volumetric[None], m.vol])[of]),
                np.ascontiguousarray((corners - corners.mean(axis=1, keepdims=True)).reshape(len(of), 24)))

    def rotations(self, q: np.ndarray) -> np.ndarray:
        """``(voxels, 3, 3)``: each voxel's R (polar decomposition of F at its centre) at ``q``."""
        out = np.empty((len(self.voxels), 3, 3))
        _rotations_at(self.settled, self.modes, np.ascontiguousarray(q, float), self.grads, out)
        return out

    def turned_modes(self, rot: np.ndarray, which: np.ndarray) -> np.ndarray:
        """``(len(which), 24, r)``: R_eᵀ V_e node by node for the voxels at positions ``which``."""
        modes = self.modes[which]
        return np.matmul(rot.transpose(0, 2, 1)[:, None], modes.reshape(len(which), 8, 3, -1)).reshape(modes.shape)

    def turned_since(self, rot: np.ndarray, taken: np.ndarray, tolerance_m: float) -> np.ndarray:
        """Positions of the voxels whose rotation ``rot`` differs from ``taken`` by more than
        ``tolerance_m`` over the voxel's side (radians)."""
        return np.flatnonzero(np.abs(rot - taken).reshape(len(rot), 9).max(axis=1) > tolerance_m / self.side_m)


class TurnedViscosity:
    """Eq. 16's viscosity of a corotational reduced model on ECSW's sampled voxels: each one's
    shear rate read in its own frame (``B0 R_eᵀ V_e q̇``) and its block ``(R_eᵀ V_e)ᵀ C_e (R_eᵀ
    V_e)``, both kept while the voxel's rotation stays within the tolerance of the one they were
    taken at.

    ``rate_modes`` ``(rated, 6, r)`` and ``viscous`` ``(sampled, r(r+1)/2)`` (single precision,
    ECSW-weighted upper triangles) are the reduced model's arrays at R = I, updated in place;
    ``rated`` the voxels whose rates a step reads (the sample's, and the friction's, whose rates
    only weigh in its normal reactions and stay on the reference frame, as those reactions'
    elasticity does), ``sampled_in_rated`` the sampled voxels' positions among them, ``weights``
    theirs."""

    def __init__(self, matrices, node_modes_m: np.ndarray, settled_m: np.ndarray, rated: np.ndarray,
                 sampled_in_rated: np.ndarray, weights: np.ndarray, upper: tuple, rate_modes: np.ndarray,
                 viscous: np.ndarray):
        m = matrices
        self.rows = np.asarray(sampled_in_rated, np.int64)
        self.frames = VoxelFrames(m, node_modes_m, settled_m, np.asarray(rated)[self.rows])
        of = self.frames.block_of[self.frames.voxels]
        self.centre_b = np.concatenate([m.cube.centre_b[None], m.b0])[of]                 # (sampled, 6, 24)
        self.blocks = np.concatenate([m.cube.viscous[None], m.visc])[of]                  # (sampled, 24, 24)
        self.weights = np.asarray(weights, float)
        self.upper = upper
        self.rate_modes, self.viscous = rate_modes, viscous
        self.taken = np.broadcast_to(np.eye(3), (len(self.rows), 3, 3)).copy()

    def update(self, q: np.ndarray, tolerance_m: float) -> None:
        """Turn the parts of the sampled voxels that turned at ``q`` (class docstring)."""
        rot = self.frames.rotations(q)
        which = self.frames.turned_since(rot, self.taken, tolerance_m)
        if not len(which):
            return
        self.taken[which] = rot[which]
        turned = self.frames.turned_modes(rot[which], which)
        self.rate_modes[self.rows[which]] = np.matmul(self.centre_b[which], turned)
        parts = np.matmul(turned.transpose(0, 2, 1), np.matmul(self.blocks[which], turned))
        self.viscous[which] = (parts[:, self.upper[0], self.upper[1]] * self.weights[which, None]).astype(np.float32)


class CandidateForces:
    """The corotational elastic force on the friction's candidate nodes, along each one's normal
    (N): the friction's normal reactions from the turned elasticity, as the full model's contact
    reactions are (the small-strain rows of K read a turned sample's rigid turn as strain, of the
    order of what its weight strains it by).

    ``voxels`` the voxels that touch a candidate; ``nodes`` ``(c,)`` the candidates' nodes (a node
    near two solids is two candidates), ``normals`` ``(c, 3)`` theirs."""

    def __init__(self, matrices, rest_m: np.ndarray, node_modes_m: np.ndarray, settled_m: np.ndarray,
                 voxels: np.ndarray, nodes: np.ndarray, normals: np.ndarray):
        m = matrices
        self.frames = VoxelFrames(m, node_modes_m, settled_m, voxels)
        self.dev, self.vol, self.local = self.frames.elastic_parts(m, rest_m)
        unique, self._candidate = np.unique(np.asarray(nodes, np.int64), return_inverse=True)
        position = np.full(len(rest_m), -1)
        position[unique] = np.arange(len(unique))
        self._slot = np.ascontiguousarray(position[m.elements[self.frames.voxels]])   # (voxels, 8): node, or −1
        self._n_unique = len(unique)
        self.normals = np.asarray(normals, float)
        self._k = None

    def normal_n(self, q: np.ndarray, two_g_pa: float, kappa_pa: float, which: np.ndarray | None = None
                 ) -> np.ndarray:
        """``(c,)`` each candidate's elastic force along its normal at ``q`` (N); only of the
        candidates ``which`` (a mask; the others 0: a candidate off its solid presses nothing, and
        its voxels are most of the cost)."""
        if self._k is None or self._k[0] != (two_g_pa, kappa_pa):
            self._k = ((two_g_pa, kappa_pa), two_g_pa * self.dev + kappa_pa * self.vol)
        active = np.ones(self._n_unique, np.bool_)
        if which is not None:
            active[:] = False
            active[self._candidate[np.asarray(which, bool)]] = True
        f = self.frames
        node = np.zeros((self._n_unique, 3))
        _node_forces(f.settled, f.modes, np.ascontiguousarray(q, float), self.local, f.grads, self._k[1],
                     self._slot, active, node)
        out = np.einsum("ck,ck->c", self.normals, node[self._candidate])
        return out if which is None else np.where(which, out, 0.0)


class ReducedCorotation:
    """The corotational elastic force of a voxel mesh in reduced coordinates (module docstring).

    Parameters
    ----------
    matrices
        The mesh's :class:`~hifumotion.creep.hexahedra.MeshMatrices`.
    rest_m
        ``(n, 3)`` the nodes at rest (m).
    node_modes_m
        ``(3n, r)`` the modes (m per unit q).
    settled_m
        ``(3n,)`` the settled state's displacement from rest (m): q = 0.
    snapshots
        ``(r, S)`` the snapshots' reduced coordinates: the states ECSW is fitted on (with q = 0).
    tolerance
        ECSW's relative error on those states' reduced forces; 0 sums every voxel.
    samples
        How many of the snapshots, evenly spread, the fit reads.
    """

    def __init__(self, matrices, rest_m: np.ndarray, node_modes_m: np.ndarray, settled_m: np.ndarray,
                 snapshots: np.ndarray, tolerance: float, samples: int):
        m = matrices
        n_el, r = len(m.elements), node_modes_m.shape[1]
        every = VoxelFrames(m, node_modes_m, settled_m, np.arange(n_el))
        dev, vol, local = every.elastic_parts(m, rest_m)
        voxels, self.weights, self.residual = np.arange(n_el), np.ones(n_el), 0.0
        if tolerance > 0 and n_el:
            pick = np.unique(np.linspace(0, max(snapshots.shape[1] - 1, 0), samples).astype(int))
            states = np.hstack([np.zeros((r, 1)), snapshots[:, pick]]) if snapshots.size else np.zeros((r, 1))
            columns = []
            for q in states.T:
                u = every.settled + every.modes @ q
                rot = _rotations(u, every.grads)
                for blocks in (dev, vol):
                    f = _voxel_forces(u, rot, local, blocks)                      # (voxels, 24)
                    part = np.einsum("eir,ei->re", every.modes, f)                 # (r, voxels)
                    size = np.linalg.norm(part.sum(axis=1))
                    if size > 0:
                        columns.append(part / size)
            if columns:
                voxels, self.weights, self.residual = greedy_weights(np.vstack(columns), tolerance)
        self.frames = VoxelFrames(m, node_modes_m, settled_m, voxels)
        self.local = np.ascontiguousarray(local[voxels])
        self.dev = np.ascontiguousarray(dev[voxels])
        self.vol = np.ascontiguousarray(vol[voxels])
        self._weighted_modes = self.frames.modes * self.weights[:, None, None]

    @property
    def voxels(self) -> np.ndarray:
        return self.frames.voxels

    @property
    def size(self) -> int:
        return len(self.frames.voxels)

    def at(self, q: np.ndarray, two_g_pa: float, kappa_pa: float, tolerance_m: float = 0.0) -> CorotatedForce:
        """The reduced elastic force at ``q`` and K_R,r with the rotations there.

        K_R,r is the weighted sum of each sampled voxel's ``(R_eᵀ V_e)ᵀ K_e (R_eᵀ V_e)``, kept from
        the last call (of this material) for every voxel whose rotation differs from the one its
        part was taken at by at most ``tolerance_m`` over the voxel's side (module docstring). The
        matrix only steers the step's rounds to the solution, which the force decides."""
        q = np.ascontiguousarray(q, float)
        f = self.frames
        rot = np.empty((self.size, 3, 3))
        force = np.zeros(f.modes.shape[2])
        _forces(f.settled, f.modes, q, self.local, f.grads, self.dev, self.vol, float(two_g_pa),
                float(kappa_pa), self.weights, rot, force)
        # (material, rotations the parts were taken at, the parts, their weighted sum)
        cache = getattr(self, "_parts", None)
        if cache is None or cache[0] != (two_g_pa, kappa_pa):
            parts = self._matrix_parts(rot, two_g_pa, kappa_pa, np.arange(self.size))
            cache = self._parts = [(two_g_pa, kappa_pa), rot.copy(), parts, np.tensordot(self.weights, parts, axes=1)]
        else:
            turned = f.turned_since(rot, cache[1], tolerance_m)
            if len(turned):
                new = self._matrix_parts(rot[turned], two_g_pa, kappa_pa, turned)
                cache[3] = cache[3] + np.tensordot(self.weights[turned], new - cache[2][turned], axes=1)
                cache[1][turned] = rot[turned]
                cache[2][turned] = new
        return CorotatedForce(rot, force, cache[3], q.copy())

    def _matrix_parts(self, rot: np.ndarray, two_g_pa: float, kappa_pa: float, which: np.ndarray) -> np.ndarray:
        """``(len(which), r, r)``: ``(R_eᵀ V_e)ᵀ K_e (R_eᵀ V_e)`` of the sampled voxels at positions ``which``."""
        k = two_g_pa * self.dev[which] + kappa_pa * self.vol[which]
        turned = self.frames.turned_modes(rot, which)
        parts = np.matmul(turned.transpose(0, 2, 1), np.matmul(k, turned))
        return 0.5 * (parts + parts.transpose(0, 2, 1))

    def moved(self, taken: CorotatedForce, q: np.ndarray, tolerance_m: float) -> bool:
        """Whether a sampled voxel's rotation at ``q`` differs from ``taken``'s by more than
        ``tolerance_m`` over the voxel's side (radians; the full model's criterion)."""
        return bool(len(self.frames.turned_since(self.frames.rotations(q), taken.rotations, tolerance_m)))


@njit(cache=True)
def _node_forces(settled, modes, q, local, grads, k, slot, active, out):
    """out[slot[e, a]] += (R_e K_e (R_eᵀ x_e − X_e)) at corner a of each voxel e, for the corners
    whose node is ``active`` (slot −1: not summed)."""
    u = np.empty(24)
    z = np.empty(24)
    x = np.empty((8, 3))
    f = np.empty((3, 3))
    re = np.empty((3, 3))
    for e in range(modes.shape[0]):
        wanted = False
        for a in range(8):
            if slot[e, a] >= 0 and active[slot[e, a]]:
                wanted = True
        if not wanted:
            continue
        _voxel_at(settled[e], modes[e], q, grads[e], u, f, re)
        _turned_strain(u, local[e], re, x, z)
        for a in range(8):
            node = slot[e, a]
            if node < 0 or not active[node]:
                continue
            loc = np.zeros(3)
            for i in range(3):
                acc = 0.0
                for j in range(24):
                    acc += k[e, 3 * a + i, j] * z[j]
                loc[i] = acc
            for i in range(3):
                out[node, i] += re[i, 0] * loc[0] + re[i, 1] * loc[1] + re[i, 2] * loc[2]


@njit(cache=True)
def _voxel_at(settled, modes, q, grads, u, f, re):
    """u = settled + modes @ q (a voxel's 24 corner displacements), re its rotation there."""
    for i in range(24):
        acc = settled[i]
        for j in range(q.shape[0]):
            acc += modes[i, j] * q[j]
        u[i] = acc
    _centre_gradient(u, grads, f)
    polar_rotation(f, re)


@njit(cache=True)
def _turned_strain(u, local, re, x, z):
    """z = R_eᵀ x − X_e node by node (x the corners from their centre; ``local`` X_e from its own)."""
    c = np.zeros(3)
    for a in range(8):
        for i in range(3):
            x[a, i] = local[3 * a + i] + u[3 * a + i]
            c[i] += x[a, i] / 8.0
    for a in range(8):
        for i in range(3):
            acc = 0.0
            for j in range(3):
                acc += re[j, i] * (x[a, j] - c[j])          # (R_eᵀ x)_i
            z[3 * a + i] = acc - local[3 * a + i]


@njit(cache=True)
def _forces(settled, modes, q, local, grads, dev, vol, two_g, kappa, weights, rot, force):
    """Each sampled voxel's rotation at q into ``rot``; Σ_e w_e V_eᵀ R_e K_e (R_eᵀ x_e − X_e) into ``force``."""
    r = q.shape[0]
    u = np.empty(24)
    x = np.empty((8, 3))
    z = np.empty(24)
    f = np.empty((3, 3))
    for e in range(modes.shape[0]):
        re = rot[e]
        _voxel_at(settled[e], modes[e], q, grads[e], u, f, re)
        _turned_strain(u, local[e], re, x, z)
        w = weights[e]
        for a in range(8):
            loc = np.zeros(3)
            for i in range(3):
                row = 3 * a + i
                acc = 0.0
                for j in range(24):
                    acc += (two_g * dev[e, row, j] + kappa * vol[e, row, j]) * z[j]
                loc[i] = acc
            for i in range(3):
                fi = w * (re[i, 0] * loc[0] + re[i, 1] * loc[1] + re[i, 2] * loc[2])
                for k in range(r):
                    force[k] += modes[e, 3 * a + i, k] * fi


def _rotations(u: np.ndarray, grads: np.ndarray) -> np.ndarray:
    """``(voxels, 3, 3)`` R of F = R U at each voxel's centre, F = I + Σ_a u_a ⊗ ∇N_a; ``u``
    ``(voxels, 24)`` its corners' displacements (m), ``grads`` ``(voxels, 8, 3)`` (1/m). An
    inverted voxel takes the nearest proper rotation (as :mod:`hifumotion.creep.corotation`)."""
    out = np.empty((len(u), 3, 3))
    _rotations_into(np.ascontiguousarray(u, float), np.ascontiguousarray(grads, float), out)
    return out


@njit(cache=True)
def _rotations_into(u, grads, out):
    f = np.empty((3, 3))
    for e in range(u.shape[0]):
        _centre_gradient(u[e], grads[e], f)
        polar_rotation(f, out[e])


@njit(cache=True)
def _rotations_at(settled, modes, q, grads, out):
    """out[e] = R of voxel e at q (its corners' displacement ``settled[e] + modes[e] @ q``)."""
    u = np.empty(24)
    f = np.empty((3, 3))
    for e in range(modes.shape[0]):
        _voxel_at(settled[e], modes[e], q, grads[e], u, f, out[e])


@njit(cache=True)
def _centre_gradient(u, grads, f):
    """f = I + Σ_a u_a ⊗ ∇N_a: ``u`` (24,) a voxel's corner displacements, ``grads`` (8, 3)."""
    for i in range(3):
        for j in range(3):
            f[i, j] = 1.0 if i == j else 0.0
    for a in range(8):
        for i in range(3):
            for j in range(3):
                f[i, j] += u[3 * a + i] * grads[a, j]


def _voxel_forces(u: np.ndarray, rot: np.ndarray, local: np.ndarray, k: np.ndarray) -> np.ndarray:
    """``(voxels, 24)`` R_e K_e (R_eᵀ x_e − X_e) (N): ``local`` the corners at rest from the voxel's
    centre (m), ``u`` their displacements; a translation of the voxel is K's null space, so the
    corners are taken from their own centre."""
    x = (local + u).reshape(-1, 8, 3)
    x = x - x.mean(axis=1, keepdims=True)
    z = (x @ rot).reshape(-1, 24) - local                      # R_eᵀ x, node by node, less X_e
    f = np.matmul(k, z[:, :, None])[:, :, 0].reshape(-1, 8, 3)
    return (f @ rot.transpose(0, 2, 1)).reshape(-1, 24)        # R_e f, node by node


__all__ = ["CandidateForces", "CorotatedForce", "ReducedCorotation", "TurnedViscosity", "VoxelFrames"]
