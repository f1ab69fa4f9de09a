"""Trilinear hexahedra on the voxel mesh: element matrices and their assembly (SI).

Small-strain elasticity, ``σ = λ tr(ε) I + 2 G ε`` — the small-strain limit of the
paper's Eq. 13–14 with the ½ of docs/decisions.md — integrated over each voxel with
**selective reduced integration**: the deviatoric part at the 2 × 2 × 2 Gauss points,
the volumetric part at the centre (Hughes 1980). Full integration of a nearly
incompressible solid (ν = 0.47) locks: its trilinear cubes cannot change shape without
changing volume at every Gauss point. The deviatoric part, fully integrated, leaves no
zero-energy (hourglass) mode, so no hourglass control is needed.

The rheological viscosity (Eq. 12 with Eq. 16's μ) becomes the Kelvin–Voigt viscous
stress ``σ_v = 2 μ ε̇`` with μ per voxel from its equivalent shear rate
``γ̇ = √(2 dev ε̇ : dev ε̇)`` — the continuum form of the paper's pair viscosity, whose
``|v_ij × r_ij| / |r_ij|²`` is a pair's shear rate; unlike the pair form it does not
resist a rigid rotation (docs/decisions.md).

Every voxel is the same cube, so each matrix is one 24 × 24 block scaled per voxel and
summed into a CSR pattern built once (:class:`Assembly`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit

_XI = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)

#: Deviatoric and volumetric projectors on Voigt strain (xx, yy, zz, xy, yz, zx; engineering shear).
_DEV = np.zeros((6, 6))
_DEV[:3, :3] = np.eye(3) - 1.0 / 3.0
_DEV[3:, 3:] = 0.5 * np.eye(3)
_VOL = np.zeros((6, 6))
_VOL[:3, :3] = 1.0
_FULL = np.zeros((6, 6))
_FULL[:3, :3] = np.eye(3)
_FULL[3:, 3:] = 0.5 * np.eye(3)


def strain_matrix(point: np.ndarray, side_m: float) -> np.ndarray:
    """``B`` (6 × 24, 1/m) of a cube of side ``side_m`` at the reference point ``point`` ∈ [−1, 1]³."""
    p = np.asarray(point, float)
    grad = np.empty((8, 3))
    for d in range(3):
        o = [k for k in range(3) if k != d]
        grad[:, d] = _XI[:, d] * (1 + _XI[:, o[0]] * p[o[0]]) * (1 + _XI[:, o[1]] * p[o[1]]) / 8.0
    grad *= 2.0 / side_m
    b = np.zeros((6, 24))
    for a in range(8):
        gx, gy, gz = grad[a]
        b[0, 3 * a] = gx
        b[1, 3 * a + 1] = gy
        b[2, 3 * a + 2] = gz
        b[3, 3 * a], b[3, 3 * a + 1] = gy, gx
        b[4, 3 * a + 1], b[4, 3 * a + 2] = gz, gy
        b[5, 3 * a], b[5, 3 * a + 2] = gz, gx
    return b


@dataclass(frozen=True)
class CubeMatrices:
    """The unit matrices of one cube of side ``side_m`` (m).

    ``K_e = 2 G · deviatoric + κ · volumetric`` (κ = λ + 2G/3, N/m per Pa) and
    ``C_e = μ · viscous`` (N·s/m per Pa·s); ``centre_b`` is B at the centre (rates).
    """

    side_m: float
    deviatoric: np.ndarray
    volumetric: np.ndarray
    viscous: np.ndarray
    centre_b: np.ndarray


def cube_matrices(side_m: float) -> CubeMatrices:
    """Element matrices of a cube (module docstring); 2 × 2 × 2 Gauss, volumetric at 1 point."""
    weight = (side_m / 2.0) ** 3
    dev = np.zeros((24, 24))
    visc = np.zeros((24, 24))
    for point in _XI / math.sqrt(3.0):
        b = strain_matrix(point, side_m)
        dev += b.T @ _DEV @ b * weight
        visc += 2.0 * b.T @ _FULL @ b * weight
    b0 = strain_matrix(np.zeros(3), side_m)
    vol = b0.T @ _VOL @ b0 * 8.0 * weight
    return CubeMatrices(side_m, dev, vol, visc, b0)


@njit(cache=True)
def _scatter(emap, block, scale, data):
    """data[emap[e, p, q]] += scale[e] · block[p, q] (serial: elements share entries)."""
    for e in range(emap.shape[0]):
        s = scale[e]
        if s == 0.0:
            continue
        for p in range(24):
            for q in range(24):
                data[emap[e, p, q]] += s * block[p, q]


@njit(cache=True)
def _element_rates(velocity, elements, which, blocks, block_of, out):
    """Equivalent shear rate √(2 dev ε̇ : dev ε̇) (1/s) at the centres of the voxels ``which``,
    voxel ``which[m]`` with the centre B ``blocks[block_of[m]]``."""
    for m in range(which.shape[0]):
        e = which[m]
        b0 = blocks[block_of[m]]
        rate = np.zeros(6)
        for a in range(8):
            n = elements[e, a]
            for c in range(3):
                vc = velocity[n, c]
                for r in range(6):
                    rate[r] += b0[r, 3 * a + c] * vc
        tr = (rate[0] + rate[1] + rate[2]) / 3.0
        d0 = rate[0] - tr
        d1 = rate[1] - tr
        d2 = rate[2] - tr
        # engineering shear γ = 2 ε_ij: dev:dev = Σ d_ii² + ½ Σ γ²
        dd = d0 * d0 + d1 * d1 + d2 * d2 + 0.5 * (rate[3] ** 2 + rate[4] ** 2 + rate[5] ** 2)
        out[e] = math.sqrt(2.0 * dd)


class Assembly:
    """The global CSR pattern of a voxel mesh and the map from element entries into it."""

    def __init__(self, elements: np.ndarray, n_nodes: int):
        self.elements = np.ascontiguousarray(elements, np.int64)
        self.size = 3 * int(n_nodes)
        dof = (3 * self.elements[:, :, None] + np.arange(3)).reshape(len(self.elements), 24)
        rows = np.repeat(dof, 24, axis=1).ravel()
        cols = np.tile(dof, (1, 24)).ravel()
        pattern = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(self.size, self.size))
        pattern.sort_indices()
        self.indptr, self.indices = pattern.indptr, pattern.indices
        # position of (row, col) in the CSR data, by binary search in the sorted row
        pos = _positions(self.indptr, self.indices, rows, cols)
        self.emap = pos.reshape(len(self.elements), 24, 24)


@njit(cache=True)
def _positions(indptr, indices, rows, cols):
    out = np.empty(len(rows), np.int64)
    for k in range(len(rows)):
        lo = indptr[rows[k]]
        hi = indptr[rows[k] + 1]
        c = cols[k]
        while lo < hi:  # binary search in the sorted row
            mid = (lo + hi) // 2
            if indices[mid] < c:
                lo = mid + 1
            else:
                hi = mid
        out[k] = lo
    return out


__all__ = ["CubeMatrices", "cube_matrices", "strain_matrix", "Assembly", "deformation_gradient"]


@njit(cache=True)
def deformation_gradient(u, nodes, g, f):
    """Fill ``f`` (3 × 3) with F = I + Σ_a u_a ⊗ ∇N_a of the voxel whose corners are ``nodes`` (8),
    ``g`` (8 × 3, 1/m) the reference gradients ∇N_a at the point and ``u`` (n, 3) the node
    displacements (m)."""
    for i in range(3):
        for j in range(3):
            f[i, j] = 1.0 if i == j else 0.0
    for a in range(8):
        n = nodes[a]
        for i in range(3):
            ui = u[n, i]
            for j in range(3):
                f[i, j] += ui * g[a, j]


@njit(cache=True)
def _shape_gradients(p0, p1, p2):
    """∂N_a/∂ξ (8 × 3) of the trilinear shape functions at (ξ, η, ζ)."""
    out = np.empty((8, 3))
    for a in range(8):
        s0, s1, s2 = _XI[a, 0], _XI[a, 1], _XI[a, 2]
        out[a, 0] = s0 * (1 + s1 * p1) * (1 + s2 * p2) / 8.0
        out[a, 1] = s1 * (1 + s0 * p0) * (1 + s2 * p2) / 8.0
        out[a, 2] = s2 * (1 + s0 * p0) * (1 + s1 * p1) / 8.0
    return out



@njit(cache=True)
def _b_at(x_e, p0, p1, p2, b):
    """Fill B (6 × 24, 1/m) of the hexahedron with corners ``x_e`` (8 × 3, m) at (ξ, η, ζ); return det J."""
    dn = _shape_gradients(p0, p1, p2)
    jac = np.zeros((3, 3))
    for a in range(8):
        for r in range(3):
            for c in range(3):
                jac[r, c] += dn[a, r] * x_e[a, c]  # J[r, c] = ∂x_c/∂ξ_r
    det = (jac[0, 0] * (jac[1, 1] * jac[2, 2] - jac[1, 2] * jac[2, 1])
           - jac[0, 1] * (jac[1, 0] * jac[2, 2] - jac[1, 2] * jac[2, 0])
           + jac[0, 2] * (jac[1, 0] * jac[2, 1] - jac[1, 1] * jac[2, 0]))
    if not det > 0.0:
        # a folded or flat corner: no gradient (the callers reject it by its det, conform moves
        # its nodes back); np.linalg.inv would raise on an exactly flat one
        b[:, :] = 0.0
        return det
    inv = np.linalg.inv(jac)
    for a in range(8):
        gx = inv[0, 0] * dn[a, 0] + inv[0, 1] * dn[a, 1] + inv[0, 2] * dn[a, 2]
        gy = inv[1, 0] * dn[a, 0] + inv[1, 1] * dn[a, 1] + inv[1, 2] * dn[a, 2]
        gz = inv[2, 0] * dn[a, 0] + inv[2, 1] * dn[a, 1] + inv[2, 2] * dn[a, 2]
        for r in range(6):
            for c in range(3):
                b[r, 3 * a + c] = 0.0
        b[0, 3 * a] = gx
        b[1, 3 * a + 1] = gy
        b[2, 3 * a + 2] = gz
        b[3, 3 * a] = gy
        b[3, 3 * a + 1] = gx
        b[4, 3 * a + 1] = gz
        b[4, 3 * a + 2] = gy
        b[5, 3 * a] = gz
        b[5, 3 * a + 2] = gx
    return det


@njit(cache=True)
def _general_blocks(x, elements, which, dev_p, vol_p, full_p, dev, vol, visc, b0, min_det):
    g = 1.0 / math.sqrt(3.0)
    b = np.empty((6, 24))
    x_e = np.empty((8, 3))
    for m in range(which.shape[0]):
        e = which[m]
        for a in range(8):
            for c in range(3):
                x_e[a, c] = x[elements[e, a], c]
        worst = 1e300
        for q in range(8):
            det = _b_at(x_e, _XI[q, 0] * g, _XI[q, 1] * g, _XI[q, 2] * g, b)
            worst = min(worst, det)
            db = dev_p @ b
            fb = full_p @ b
            dev[m] += (b.T @ db) * det
            visc[m] += 2.0 * (b.T @ fb) * det
        det = _b_at(x_e, 0.0, 0.0, 0.0, b)
        worst = min(worst, det)
        vol[m] += (b.T @ (vol_p @ b)) * (8.0 * det)
        b0[m] = b
        min_det[m] = worst


def general_blocks(nodes_m: np.ndarray, elements: np.ndarray, which: np.ndarray):
    """Element matrices of distorted hexahedra ``which`` (the same integration as :func:`cube_matrices`).

    Returns ``(deviatoric, volumetric, viscous, centre_b, min_det_j)``; ``min_det_j``
    (m³) is the smallest Jacobian over the integration points (> 0 for a valid element).
    """
    m = len(which)
    dev = np.zeros((m, 24, 24))
    vol = np.zeros((m, 24, 24))
    visc = np.zeros((m, 24, 24))
    b0 = np.zeros((m, 6, 24))
    min_det = np.zeros(m)
    _general_blocks(np.ascontiguousarray(nodes_m, float), elements, np.ascontiguousarray(which, np.int64),
                    _DEV, _VOL, _FULL, dev, vol, visc, b0, min_det)
    return dev, vol, visc, b0, min_det


@njit(cache=True)
def _scatter_blocks(emap, which, blocks, scale, data):
    for m in range(which.shape[0]):
        e = which[m]
        s = scale[e]
        if s == 0.0:
            continue
        for p in range(24):
            for q in range(24):
                data[emap[e, p, q]] += s * blocks[m, p, q]


class MeshMatrices:
    """Stiffness and viscosity of a voxel mesh whose boundary nodes may sit on the true surface.

    Voxels that are still exact cubes share one block (:func:`cube_matrices`); the
    others (the boundary layer of a conforming mesh) carry their own
    (:func:`general_blocks`). Raises ``ValueError`` for an inverted element.
    """

    def __init__(self, nodes_m: np.ndarray, elements: np.ndarray, side_m: float):
        self.elements = np.ascontiguousarray(elements, np.int64)
        self.cube = cube_matrices(side_m)
        self.assembly = Assembly(self.elements, len(nodes_m))
        from hifumotion.creep.voxels import CORNERS

        corners = nodes_m[self.elements]
        offset = corners - corners[:, :1]
        exact = np.abs(offset - CORNERS[None] * side_m).max(axis=(1, 2)) <= 1e-9 * side_m
        self.regular = np.flatnonzero(exact)
        self.distorted = np.flatnonzero(~exact)
        self.dev, self.vol, self.visc, self.b0, min_det = general_blocks(nodes_m, self.elements, self.distorted)
        if len(min_det) and min_det.min() <= 0:
            raise ValueError(f"{int((min_det <= 0).sum())} inverted voxels in the conforming mesh")
        self.mask = np.zeros(len(self.elements), bool)
        self.mask[self.regular] = True

    def own_blocks(self, voxels: np.ndarray) -> np.ndarray:
        """Where each of ``voxels`` has its own blocks in ``dev``/``vol``/``visc``/``b0`` (−1: an
        exact cube, which takes :attr:`cube`'s)."""
        which = np.full(len(self.elements), -1)
        which[self.distorted] = np.arange(len(self.distorted))
        return which[np.asarray(voxels)]

    def matrix(self, deviatoric: np.ndarray | float, volumetric: np.ndarray | float, viscous: np.ndarray | float
               ) -> sp.csr_matrix:
        """``Σ_e 2G_e·dev_e + κ_e·vol_e + μ_e·visc_e`` (scales per element or scalars, SI)."""
        n = len(self.elements)
        scales = [np.broadcast_to(np.asarray(s, float), (n,)) for s in (deviatoric, volumetric, viscous)]
        asm = self.assembly
        data = np.zeros(len(asm.indices))
        for block, own, scale in zip((self.cube.deviatoric, self.cube.volumetric, self.cube.viscous),
                                     (self.dev, self.vol, self.visc), scales):
            if not np.any(scale):
                continue
            _scatter(asm.emap, np.ascontiguousarray(block), np.ascontiguousarray(np.where(self.mask, scale, 0.0)), data)
            _scatter_blocks(asm.emap, self.distorted, own, np.ascontiguousarray(scale), data)
        return sp.csr_matrix((data, asm.indices, asm.indptr), shape=(asm.size, asm.size))

    def rates(self, velocity_m_s: np.ndarray) -> np.ndarray:
        """Equivalent shear rate (1/s) of every element from the node velocities (m/s)."""
        v = np.ascontiguousarray(velocity_m_s, float)
        out = np.empty(len(self.elements))
        _element_rates(v, self.elements, self.regular, self.cube.centre_b[None],
                       np.zeros(len(self.regular), np.int64), out)
        _element_rates(v, self.elements, self.distorted, self.b0, np.arange(len(self.distorted)), out)
        return out


__all__ += ["MeshMatrices", "general_blocks"]
