"""Elastic tissue with rheological viscosity (the paper's Eq. 12–16; Müller et al. 2004).

Total Lagrangian: every tissue particle keeps the neighbours it had at rest
(within the support radius, 2.5 Δx by default) and their rest offsets
``X_ij = X_j − X_i``. Per particle i (sums over its rest neighbours j):

* gradient weights ``d_ij`` of a moving-least-squares fit (Eq. 14's
  bracketed terms): the paper's linear fit ``d_ij = A_i⁻¹ X_ij w_ij`` with
  ``A_i = Σ X_ij X_ijᵀ w_ij``, or (default) the linear part of a quadratic fit,
  see :func:`rest_neighbourhoods`. Moment matrices are inverted with their
  eigenvalues floored at ``moment_floor`` × the largest, so thin or coplanar
  neighbourhoods stay well posed (the regularised moment matrix);
* displacement gradient ``∇u_i = Σ (u_j − u_i) d_ijᵀ``, deformation gradient
  ``J_i = I + ∇u_i`` (the paper's Jacobian);
* Green–Saint-Venant strain ``ε = ½ (JᵀJ − I)`` (Eq. 13; see below for the ½),
  Hookean stress ``σ = λ tr(ε) I + 2 G ε`` from Young's modulus and Poisson's
  ratio, first Piola stress ``P = J σ``;
* volume conservation (Eq. 15–16): energy ``k_v (det J − 1)² / 2`` per unit
  volume adds ``k_v (det J − 1) cof(J)`` to ``P``; ``cof(J)``'s rows are
  ``J₂×J₃, J₃×J₁, J₁×J₂`` exactly as in Eq. 16 (the paper's ‖J‖ is det J).

The elastic force of Eq. 14 is the gradient of that energy. It acts on j as
``−v_i P_i d_ij`` and on i as ``+v_i P_i Σ_j d_ij``; gathering both halves
onto particle i gives ``f_i = Σ_j (v_i P_i d_ij − v_j P_j d_ji)`` — pairwise
equal and opposite, so momentum is conserved, and no scatter is needed.

Options (switchable, defaults in :class:`TissueParameters`):

* **corotated** (Becker et al. 2009): ``J = R U`` by polar decomposition,
  linear strain ``sym(RᵀJ) − I``, ``P = R σ``: exact under large rotations;
* **hourglass control** (Ganzenmüller 2015): penalises the part of each
  pair's current offset that ``J_i`` does not explain — zero-energy modes of
  the particle lattice — with a pair force ``−α/2 · v_i v_j w_ij E /|X_ij|² ·
  (δ_i + δ_j) x̂_ij``, zero for any affine deformation;
* **rheological viscosity** (Eq. 12 between tissue particles):
  ``f_i = v_i Σ v_j μ_ij (v_j − v_i) ∇²W_visc`` with
  ``μ_ij = β₁ (sin θ |v_ij| / |r_ij|)^β₂ = β₁ (|v_ij × r_ij| / |r_ij|²)^β₂``,
  its rate floored at ``rate_floor`` (for β₂ < 0) and μ capped at ``mu_max``.

The paper (after Müller 2004) writes ``ε = JᵀJ − I`` and ``f = −2 v J σ d``:
that is twice the Green strain and makes the material four times stiffer than
its Young's modulus in small strain. The standard ½ is used here so that E and
ν mean what they say; the validation cases check it (docs/decisions.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange
from scipy.spatial import cKDTree

from hifumotion.particles.viscosity import rheological_mu
from hifumotion.rheology import MU_MAX_PA_S, RATE_FLOOR_PER_S
from hifumotion import paper



@dataclass(frozen=True)
class TissueParameters:
    """Material of the elastic tissue (SI).

    Attributes
    ----------
    youngs_modulus_pa, poisson_ratio
        E (Pa) and ν (−) of the Hookean stress (Table 3: 13 kPa, 0.47).
    volume_stiffness_pa
        k_v (Pa) of the volume-conservation force (Eq. 15–16). Default 0: ν already
        sets the bulk stiffness; raise it to resist inversion under large compression.
    beta1, beta2
        Rheological viscosity μ = β₁ rate^β₂ (β₁ in Pa·s^(1+β₂), β₂ dimensionless; Table 3: 1, 0.5).
    mu_max_pa_s
        Cap on the rheological viscosity (Pa·s), where a small |r_ij| would blow it up.
    rate_floor_per_s
        Floor of the shear rate (1/s) in μ (:mod:`hifumotion.rheology`).
    hourglass
        α of the hourglass control (dimensionless, 0 switches it off).
    corotated
        Use the corotated linear formulation instead of Saint-Venant–Kirchhoff.
    moment_floor
        Eigenvalue floor of the moment matrix, relative to its largest eigenvalue.
    mls_order
        1: the paper's linear MLS gradient; 2: quadratic MLS (default), exact for
        bending at the surface (see :func:`rest_neighbourhoods`).
    support_factor
        Support radius of the rest neighbourhoods in particle spacings. A quadratic fit
        needs more than two layers of neighbours at a surface: 2.5 by default.
    """

    youngs_modulus_pa: float = paper.YOUNGS_MODULUS_PA
    poisson_ratio: float = paper.POISSON_RATIO
    volume_stiffness_pa: float = 0.0
    beta1: float = paper.BETA1
    beta2: float = paper.BETA2
    mu_max_pa_s: float = MU_MAX_PA_S
    rate_floor_per_s: float = RATE_FLOOR_PER_S
    hourglass: float = 1.0
    corotated: bool = False
    moment_floor: float = 1e-4
    mls_order: int = 2
    support_factor: float = 2.5

    def lame(self) -> tuple[float, float]:
        """(λ, G) in Pa."""
        e, nu = self.youngs_modulus_pa, self.poisson_ratio
        if not (e > 0):
            raise ValueError(f"youngs_modulus_pa must be > 0, got {e}")
        if not (-1.0 < nu < 0.5):
            raise ValueError(f"poisson_ratio must be in (-1, 0.5), got {nu}")
        return e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))

    def p_wave_speed(self, density_kg_m3: float) -> float:
        """Speed of the fastest elastic wave, √((λ + 2G + k_v)/ρ) (m/s)."""
        lam, g = self.lame()
        return math.sqrt((lam + 2 * g + self.volume_stiffness_pa) / density_kg_m3)


@dataclass
class RestNeighbourhoods:
    """Rest-state neighbourhoods of the tissue particles (CSR; indices local to the tissue).

    ``neighbours[start[i]:start[i+1]]`` are i's rest neighbours, ``weight`` their
    w_ij (1/m³), ``gradient`` the MLS gradient weights d_ij (1/m: ∇u_i = Σ (u_j − u_i) d_ijᵀ)
    and ``reverse[k]`` the position of the pair (j, i) when ``k`` is the pair (i, j).
    Each row is sorted by rest distance; ``start[i] … near_end[i] − 1`` are the pairs
    closer than ``near_m`` (the SPH support h), where the pair forces (hourglass,
    rheological viscosity) act.
    """

    start: np.ndarray
    neighbours: np.ndarray
    weight: np.ndarray
    gradient: np.ndarray
    reverse: np.ndarray
    support_m: float
    order: int
    near_end: np.ndarray
    near_m: float


def _quadratic_basis(xij: np.ndarray, scale: float) -> np.ndarray:
    q = xij / scale
    a, b, c = q[:, 0], q[:, 1], q[:, 2]
    return np.stack([a, b, c, a * a, b * b, c * c, a * b, b * c, c * a], axis=1)


def _mls_gradient(i, xij, w, n, support_m, order, moment_floor):
    """Gradient weights d_ij (1/m) of an MLS fit of the given order with weights ``w``."""
    basis = xij / support_m if order == 1 else _quadratic_basis(xij, support_m)
    m = basis.shape[1]
    moment = np.zeros((n, m, m))
    np.add.at(moment, i, w[:, None, None] * basis[:, :, None] * basis[:, None, :])
    vals, vecs = np.linalg.eigh(moment)
    top = np.maximum(vals[:, -1:], 1e-300)
    vals = np.maximum(vals, moment_floor * top)
    inv = np.einsum("nij,nj,nkj->nik", vecs, 1.0 / vals, vecs)
    inv[top[:, 0] <= 1e-300] = 0.0
    return np.einsum("kab,kb->ka", inv[i][:, :3, :], basis * w[:, None]) / support_m


def rest_neighbourhoods(rest_m: np.ndarray, support_m: float, moment_floor: float = 1e-3,
                        order: int = 2, near_m: float | None = None) -> RestNeighbourhoods:
    """Rest neighbourhoods and MLS gradient weights of particles at ``rest_m`` (m).

    ``order=1`` is the paper's linear moving least squares (Müller et al. 2004):
    ``d_ij = A_i⁻¹ X_ij w_ij`` with ``A_i = Σ X_ij X_ijᵀ w_ij``. ``order=2`` fits a
    quadratic per neighbourhood and keeps its linear part, so the gradient stays
    exact for quadratic displacement fields even where the neighbourhood is
    one-sided (the surface): a bent beam then has the right stiffness, where the
    linear fit under-reads the surface strain. Moment matrices are inverted with
    their eigenvalues floored at ``moment_floor`` × the largest (regularised).

    With ``order=2`` and ``near_m`` < ``support_m``, a particle whose neighbourhood
    within ``near_m`` is point-symmetric (the interior of a lattice) uses the linear
    fit over that smaller radius instead: its odd moments vanish, so it is exact for
    quadratic fields too, at half the pairs; pairs that neither end then needs are
    dropped. The result is the same operator on quadratic fields, ≈ 40 % cheaper.
    """
    from hifumotion.particles.kernels import kernel

    if order not in (1, 2):
        raise ValueError(f"MLS order must be 1 or 2, got {order}")
    x0 = np.ascontiguousarray(rest_m, np.float64)
    n = len(x0)
    near_m = support_m if near_m is None else float(near_m)
    tree = cKDTree(x0)
    pairs = tree.query_pairs(support_m, output_type="ndarray")
    i = np.concatenate([pairs[:, 0], pairs[:, 1]]).astype(np.int64)
    j = np.concatenate([pairs[:, 1], pairs[:, 0]]).astype(np.int64)
    xij = x0[j] - x0[i]
    dist = np.linalg.norm(xij, axis=1)
    w = kernel(dist, support_m)
    grad = _mls_gradient(i, xij, w, n, support_m, order, moment_floor)
    if order == 2 and near_m < support_m:
        w_near = kernel(dist, near_m)
        scale = np.bincount(i, w_near * dist ** 3, n) + 1e-300
        odd = np.zeros(n)  # first and third moments, relative: zero for a symmetric neighbourhood
        for a in range(3):
            odd += np.abs(np.bincount(i, w_near * xij[:, a], n)) / scale * near_m ** 2
            for b in range(a, 3):
                for c in range(b, 3):
                    odd += np.abs(np.bincount(i, w_near * xij[:, a] * xij[:, b] * xij[:, c], n)) / scale
        symmetric = odd < 1e-9
        linear = _mls_gradient(i, xij, w_near, n, near_m, 1, moment_floor)
        grad = np.where(symmetric[i][:, None], linear, grad)
        keep = (dist < near_m) | ~symmetric[i] | ~symmetric[j]
        i, j, xij, dist, w, grad = i[keep], j[keep], xij[keep], dist[keep], w[keep], grad[keep]
    order_idx = np.lexsort((j, dist, i))
    i, j, dist, w, grad = i[order_idx], j[order_idx], dist[order_idx], w[order_idx], grad[order_idx]
    start = np.zeros(n + 1, np.int64)
    np.add.at(start, i + 1, 1)
    start = np.cumsum(start)
    near_end = start[:-1] + np.bincount(i[dist < near_m], minlength=n).astype(np.int64)
    # the reverse pair (j, i) of each pair (i, j)
    key = i * n + j
    by_key = np.argsort(key)
    reverse = by_key[np.searchsorted(key[by_key], j * n + i)].astype(np.int64)
    return RestNeighbourhoods(start, j, w, np.ascontiguousarray(grad), reverse,
                              float(support_m), order, near_end, near_m)


@njit(cache=True, inline="always")
def _det3(m):
    return (m[0, 0] * (m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1])
            - m[0, 1] * (m[1, 0] * m[2, 2] - m[1, 2] * m[2, 0])
            + m[0, 2] * (m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]))


@njit(cache=True)
def _polar_rotation(f):
    """Rotation of F = R U by Higham's scaled Newton iteration (F assumed det > 0)."""
    r = f.copy()
    for _ in range(30):
        d = _det3(r)
        if abs(d) < 1e-300:
            break
        inv_t = np.empty((3, 3))
        # cofactor / det = inverse transpose
        inv_t[0, 0] = (r[1, 1] * r[2, 2] - r[1, 2] * r[2, 1]) / d
        inv_t[0, 1] = (r[1, 2] * r[2, 0] - r[1, 0] * r[2, 2]) / d
        inv_t[0, 2] = (r[1, 0] * r[2, 1] - r[1, 1] * r[2, 0]) / d
        inv_t[1, 0] = (r[0, 2] * r[2, 1] - r[0, 1] * r[2, 2]) / d
        inv_t[1, 1] = (r[0, 0] * r[2, 2] - r[0, 2] * r[2, 0]) / d
        inv_t[1, 2] = (r[0, 1] * r[2, 0] - r[0, 0] * r[2, 1]) / d
        inv_t[2, 0] = (r[0, 1] * r[1, 2] - r[0, 2] * r[1, 1]) / d
        inv_t[2, 1] = (r[0, 2] * r[1, 0] - r[0, 0] * r[1, 2]) / d
        inv_t[2, 2] = (r[0, 0] * r[1, 1] - r[0, 1] * r[1, 0]) / d
        g = abs(d) ** (-1.0 / 3.0)
        change = 0.0
        for a in range(3):
            for b in range(3):
                new = 0.5 * (g * r[a, b] + inv_t[a, b] / g)
                change = max(change, abs(new - r[a, b]))
                r[a, b] = new
        if change < 1e-12:
            break
    return r


@njit(cache=True, inline="always")
def _matmul(a, b, out):
    for r in range(3):
        for c in range(3):
            out[r, c] = a[r, 0] * b[0, c] + a[r, 1] * b[1, c] + a[r, 2] * b[2, c]


@njit(cache=True, inline="always")
def _matmul_tn(a, b, out):
    """out = aᵀ b."""
    for r in range(3):
        for c in range(3):
            out[r, c] = a[0, r] * b[0, c] + a[1, r] * b[1, c] + a[2, r] * b[2, c]


@njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
def stress_pass(x, x0, first, start, nbr, grad_w, volume, lam, g, k_v, corotated,
                deform, b_mat, strain, work):
    """Eq. 13–16 per tissue particle: J (into ``deform``), ``B = v P`` (into ``b_mat``).

    ``x``, ``x0``: current and rest positions of *all* particles / of the tissue (m);
    ``first``: index of the first tissue particle in ``x``. ``strain`` receives the
    equivalent (von Mises) Green strain for output; ``work`` is scratch ``(n, 4, 3, 3)``.
    """
    n = x0.shape[0]
    for i in prange(n):
        gi = first + i
        ui0 = x[gi, 0] - x0[i, 0]
        ui1 = x[gi, 1] - x0[i, 1]
        ui2 = x[gi, 2] - x0[i, 2]
        f = deform[i]
        eps = work[i, 0]
        sig = work[i, 1]
        p = work[i, 2]
        tmp = work[i, 3]
        for a in range(3):
            for b in range(3):
                f[a, b] = 0.0
        for k in range(start[i], start[i + 1]):
            j = nbr[k]
            gj = first + j
            du0 = x[gj, 0] - x0[j, 0] - ui0
            du1 = x[gj, 1] - x0[j, 1] - ui1
            du2 = x[gj, 2] - x0[j, 2] - ui2
            d0 = grad_w[k, 0]
            d1 = grad_w[k, 1]
            d2 = grad_w[k, 2]
            f[0, 0] += du0 * d0
            f[0, 1] += du0 * d1
            f[0, 2] += du0 * d2
            f[1, 0] += du1 * d0
            f[1, 1] += du1 * d1
            f[1, 2] += du1 * d2
            f[2, 0] += du2 * d0
            f[2, 1] += du2 * d1
            f[2, 2] += du2 * d2
        for a in range(3):
            f[a, a] += 1.0
        if corotated:
            rot = _polar_rotation(f)
            _matmul_tn(rot, f, tmp)
            for a in range(3):
                for b in range(3):
                    eps[a, b] = 0.5 * (tmp[a, b] + tmp[b, a])
                eps[a, a] -= 1.0
        else:
            _matmul_tn(f, f, tmp)
            for a in range(3):
                for b in range(3):
                    eps[a, b] = 0.5 * tmp[a, b]
                eps[a, a] -= 0.5
        tr = eps[0, 0] + eps[1, 1] + eps[2, 2]
        for a in range(3):
            for b in range(3):
                sig[a, b] = 2.0 * g * eps[a, b]
            sig[a, a] += lam * tr
        if corotated:
            _matmul(rot, sig, p)
        else:
            _matmul(f, sig, p)
        if k_v != 0.0:
            det = _det3(f)
            scale = k_v * (det - 1.0)
            # cof(J): rows J2×J3, J3×J1, J1×J2 (Eq. 16)
            p[0, 0] += scale * (f[1, 1] * f[2, 2] - f[1, 2] * f[2, 1])
            p[0, 1] += scale * (f[1, 2] * f[2, 0] - f[1, 0] * f[2, 2])
            p[0, 2] += scale * (f[1, 0] * f[2, 1] - f[1, 1] * f[2, 0])
            p[1, 0] += scale * (f[2, 1] * f[0, 2] - f[2, 2] * f[0, 1])
            p[1, 1] += scale * (f[2, 2] * f[0, 0] - f[2, 0] * f[0, 2])
            p[1, 2] += scale * (f[2, 0] * f[0, 1] - f[2, 1] * f[0, 0])
            p[2, 0] += scale * (f[0, 1] * f[1, 2] - f[0, 2] * f[1, 1])
            p[2, 1] += scale * (f[0, 2] * f[1, 0] - f[0, 0] * f[1, 2])
            p[2, 2] += scale * (f[0, 0] * f[1, 1] - f[0, 1] * f[1, 0])
        vi = volume[i]
        for a in range(3):
            for b in range(3):
                b_mat[i, a, b] = vi * p[a, b]
        dev = 0.0
        m = tr / 3.0
        for a in range(3):
            for b in range(3):
                e = eps[a, b] - (m if a == b else 0.0)
                dev += e * e
        strain[i] = math.sqrt(2.0 / 3.0 * dev)


def pair_constants(rest: RestNeighbourhoods, rest_m: np.ndarray, volume_m3: np.ndarray,
                   youngs_modulus_pa: float, hourglass: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-pair constants of :func:`force_pass`: rest offsets X_ij (m) and the hourglass
    coefficient ``−α/2 v_i v_j w_ij E / |X_ij|²`` (N/m²)."""
    i = np.repeat(np.arange(len(rest.start) - 1), np.diff(rest.start))
    offsets = np.ascontiguousarray(rest_m[rest.neighbours] - rest_m[i])
    rest2 = (offsets ** 2).sum(1)
    coef = -0.5 * hourglass * volume_m3[i] * volume_m3[rest.neighbours] * rest.weight * youngs_modulus_pa / rest2
    return offsets, np.ascontiguousarray(coef)


@njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
def force_pass(x, v, first, start, near_end, nbr, offsets, hg_coef, grad_w, grad_rev, volume,
               deform, b_mat, support, use_hourglass, beta1, beta2, mu_max, rate_floor, force):
    """Elastic (Eq. 14–16), hourglass and rheological viscous (Eq. 12) forces (N), gathered.

    Adds into ``force[first + i]``; returns the largest viscosity used (Pa·s), for the
    viscous time-step limit. The pair forces use the pairs within ``support`` (the SPH
    h: ``start … near_end``). ``offsets``/``hg_coef`` come from :func:`pair_constants`;
    ``grad_rev[k]`` is d_ji for the pair k = (i, j) (``gradient[reverse]``, stored in
    pair order so the loop reads memory in sequence).
    """
    n = start.shape[0] - 1
    mu_seen = np.zeros(n)
    lap_coef = 45.0 / (math.pi * support ** 6)
    for i in prange(n):
        gi = first + i
        fx = 0.0
        fy = 0.0
        fz = 0.0
        mu_i = 0.0
        bi = b_mat[i]
        fi = deform[i]
        vol_i = volume[i]
        for k in range(start[i], start[i + 1]):
            j = nbr[k]
            gj = first + j
            bj = b_mat[j]
            # v_i P_i d_ij (i's own energy) − v_j P_j d_ji (j's energy, which i is part of)
            a0 = grad_w[k, 0]
            a1 = grad_w[k, 1]
            a2 = grad_w[k, 2]
            c0 = grad_rev[k, 0]
            c1 = grad_rev[k, 1]
            c2 = grad_rev[k, 2]
            fx += bi[0, 0] * a0 + bi[0, 1] * a1 + bi[0, 2] * a2 - (bj[0, 0] * c0 + bj[0, 1] * c1 + bj[0, 2] * c2)
            fy += bi[1, 0] * a0 + bi[1, 1] * a1 + bi[1, 2] * a2 - (bj[1, 0] * c0 + bj[1, 1] * c1 + bj[1, 2] * c2)
            fz += bi[2, 0] * a0 + bi[2, 1] * a1 + bi[2, 2] * a2 - (bj[2, 0] * c0 + bj[2, 1] * c1 + bj[2, 2] * c2)
        if not use_hourglass and beta1 == 0.0:
            force[gi, 0] += fx
            force[gi, 1] += fy
            force[gi, 2] += fz
            continue
        for k in range(start[i], near_end[i]):
            j = nbr[k]
            gj = first + j
            r0 = x[gj, 0] - x[gi, 0]
            r1 = x[gj, 1] - x[gi, 1]
            r2 = x[gj, 2] - x[gi, 2]
            r = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
            if r <= 0.0:
                continue
            if use_hourglass:
                # δ = (J X − x)·x̂ at both ends of the pair (Ganzenmüller 2015)
                X0 = offsets[k, 0]
                X1 = offsets[k, 1]
                X2 = offsets[k, 2]
                fj = deform[j]
                e0 = (fi[0, 0] + fj[0, 0]) * X0 + (fi[0, 1] + fj[0, 1]) * X1 + (fi[0, 2] + fj[0, 2]) * X2 - 2.0 * r0
                e1 = (fi[1, 0] + fj[1, 0]) * X0 + (fi[1, 1] + fj[1, 1]) * X1 + (fi[1, 2] + fj[1, 2]) * X2 - 2.0 * r1
                e2 = (fi[2, 0] + fj[2, 0]) * X0 + (fi[2, 1] + fj[2, 1]) * X1 + (fi[2, 2] + fj[2, 2]) * X2 - 2.0 * r2
                mag = hg_coef[k] * (e0 * r0 + e1 * r1 + e2 * r2) / (r * r)
                fx += mag * r0
                fy += mag * r1
                fz += mag * r2
            if beta1 != 0.0 and r < support:
                v0 = v[gj, 0] - v[gi, 0]
                v1 = v[gj, 1] - v[gi, 1]
                v2 = v[gj, 2] - v[gi, 2]
                mu = rheological_mu(v0, v1, v2, r0, r1, r2, r, beta1, beta2, mu_max, rate_floor)
                if mu > mu_i:
                    mu_i = mu
                sc = mu * vol_i * volume[j] * lap_coef * (support - r)
                fx += sc * v0
                fy += sc * v1
                fz += sc * v2
        force[gi, 0] += fx
        force[gi, 1] += fy
        force[gi, 2] += fz
        mu_seen[i] = mu_i
    return mu_seen.max() if n else 0.0
