"""Implicit time integration of the tissue's rheological viscosity (Eq. 12 with Eq. 16's μ).

The paper's rheological viscosity acts between tissue particles as Eq. 12,
``f_i = Σ_j c_ij (v_j − v_i)`` with the pair coefficient (kg/s)

    c_ij = μ_ij v_i v_j ∇²W_visc(r_ij, h),   μ_ij = β₁ (|v_ij × r_ij| / |r_ij|²)^β₂

(``v_i`` the rest volumes, ``∇²W_visc = 45/(π h⁶) (h − r)``). A tissue that creeps
over seconds needs μ of 10⁴–10⁵ Pa·s, and an explicit step must then stay below
``ρ Δx² / (4 μ)`` — about 10⁻⁸ s at a 1 mm spacing, a million steps per second of
tissue motion. So the viscous force is taken at the *end* of the step (backward
Euler), with μ_ij frozen at the start of the step (one Picard iteration):

    (M_i + dt Σ_j c_ij) v_i − dt Σ_j c_ij v_j = M_i v*_i,

where ``v*`` is the velocity after the explicit forces and ``M`` the (scaled)
inertia. The matrix is a weighted graph Laplacian plus a positive diagonal:
symmetric positive definite, so conjugate gradients with a Jacobi
preconditioner solve it (three right-hand sides, one per axis, same matrix).
Because ``c_ij = c_ji`` the viscous forces stay pairwise equal and opposite:
momentum is conserved exactly, and the kinetic energy can only fall, at any
step size. Components held at a prescribed velocity are boundary values.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from hifumotion import rheology

#: Eq. 16's law (:mod:`hifumotion.rheology`), compiled into the pair kernels
_viscosity_pa_s = njit(inline="always", fastmath=True, error_model="numpy")(rheology.viscosity_pa_s)


@njit(inline="always", fastmath=True, error_model="numpy")
def rheological_mu(v0, v1, v2, r0, r1, r2, r, beta1, beta2, mu_max, rate_floor):
    """Eq. 16's μ (Pa·s, :func:`hifumotion.rheology.viscosity_pa_s`) at the pair's shear rate
    ``|v_ij × r_ij| / |r_ij|²``."""
    c0 = v1 * r2 - v2 * r1
    c1 = v2 * r0 - v0 * r2
    c2 = v0 * r1 - v1 * r0
    rate = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2) / (r * r)
    return _viscosity_pa_s(rate, beta1, beta2, rate_floor, mu_max)


@njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
def pair_coefficients(x, v, first, start, near_end, nbr, volume, support, beta1, beta2, mu_max,
                      rate_floor, coef):
    """Fill ``coef[k]`` (kg/s) for the near pairs k of each tissue particle; return max μ (Pa·s).

    Pairs farther apart than ``support`` now get 0. ``x``/``v`` are the global arrays
    (SI), the tissue starting at ``first``; ``volume`` the tissue's rest volumes (m³).
    """
    n = start.shape[0] - 1
    mu_seen = np.zeros(max(n, 1))
    lap = 45.0 / (math.pi * support ** 6)
    for i in prange(n):
        gi = first + i
        mu_i = 0.0
        for k in range(start[i], near_end[i]):
            coef[k] = 0.0
            gj = first + nbr[k]
            r0 = x[gj, 0] - x[gi, 0]
            r1 = x[gj, 1] - x[gi, 1]
            r2 = x[gj, 2] - x[gi, 2]
            r = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
            if r <= 0.0 or r >= support:
                continue
            mu = rheological_mu(v[gj, 0] - v[gi, 0], v[gj, 1] - v[gi, 1], v[gj, 2] - v[gi, 2],
                                r0, r1, r2, r, beta1, beta2, mu_max, rate_floor)
            if mu > mu_i:
                mu_i = mu
            coef[k] = mu * volume[i] * volume[nbr[k]] * lap * (support - r)
        mu_seen[i] = mu_i
    return mu_seen.max()


@njit(cache=True, parallel=True, fastmath=True)
def _apply(u, first, start, near_end, nbr, coef, inertia, dt, free, out):
    """out = A u on the free components (0 on the held ones)."""
    n = start.shape[0] - 1
    for i in prange(n):
        gi = first + i
        diag = inertia[i]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for k in range(start[i], near_end[i]):
            c = dt * coef[k]
            diag += c
            gj = first + nbr[k]
            s0 += c * u[gj, 0]
            s1 += c * u[gj, 1]
            s2 += c * u[gj, 2]
        out[i, 0] = (diag * u[gi, 0] - s0) * free[i, 0]
        out[i, 1] = (diag * u[gi, 1] - s1) * free[i, 1]
        out[i, 2] = (diag * u[gi, 2] - s2) * free[i, 2]


@njit(cache=True, parallel=True, fastmath=True)
def _diagonal(start, near_end, coef, inertia, dt, out):
    n = start.shape[0] - 1
    for i in prange(n):
        d = inertia[i]
        for k in range(start[i], near_end[i]):
            d += dt * coef[k]
        out[i] = d


@njit(cache=True, parallel=True, fastmath=True)
def _dot3(a, b, first_a, first_b, n, out):
    """out[c] = Σ_i a[first_a + i, c] b[first_b + i, c] for the three axes."""
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for i in prange(n):
        s0 += a[first_a + i, 0] * b[first_b + i, 0]
        s1 += a[first_a + i, 1] * b[first_b + i, 1]
        s2 += a[first_a + i, 2] * b[first_b + i, 2]
    out[0] = s0
    out[1] = s1
    out[2] = s2


@njit(cache=True, parallel=True, fastmath=True)
def _cg_update(v, p, r, z, ap, diag, alpha, first, n):
    for i in prange(n):
        for a in range(3):
            v[first + i, a] += alpha[a] * p[first + i, a]
            r[i, a] -= alpha[a] * ap[i, a]
            z[i, a] = r[i, a] / diag[i]


@njit(cache=True, parallel=True, fastmath=True)
def _cg_direction(p, z, beta, free, first, n):
    for i in prange(n):
        for a in range(3):
            p[first + i, a] = z[i, a] + beta[a] * p[first + i, a] * free[i, a]


@njit(cache=True)
def _solve(v, first, start, near_end, nbr, coef, inertia, dt, free, guess, tol, max_iter):
    """Preconditioned CG for the three axes at once (each its own α, β); returns iterations.

    Starts from ``v* + guess`` (the last step's correction: the viscous change is smooth
    in time, so this saves iterations)."""
    n = start.shape[0] - 1
    diag = np.empty(n)
    _diagonal(start, near_end, coef, inertia, dt, diag)
    # right-hand side M v* on the free components; held ones stay in v as boundary values
    b = np.empty((n, 3))
    for i in range(n):
        for a in range(3):
            b[i, a] = inertia[i] * v[first + i, a] * free[i, a]
            v[first + i, a] += guess[i, a] * free[i, a]
    ap = np.empty((n, 3))
    _apply(v, first, start, near_end, nbr, coef, inertia, dt, free, ap)
    r = b - ap
    z = np.empty((n, 3))
    p = np.zeros((len(v), 3))   # search direction in global layout (0 outside the tissue)
    for i in range(n):
        for a in range(3):
            z[i, a] = r[i, a] / diag[i]
            p[first + i, a] = z[i, a]
    rz = np.zeros(3)
    _dot3(r, z, 0, 0, n, rz)
    bnorm = np.zeros(3)
    _dot3(b, b, 0, 0, n, bnorm)
    rr = np.zeros(3)
    pap = np.zeros(3)
    alpha = np.zeros(3)
    beta = np.zeros(3)
    new_rz = np.zeros(3)
    it = 0
    while it < max_iter:
        _dot3(r, r, 0, 0, n, rr)
        done = True
        for a in range(3):
            if rr[a] > tol * tol * max(bnorm[a], 1e-300):
                done = False
        if done:
            break
        _apply(p, first, start, near_end, nbr, coef, inertia, dt, free, ap)
        _dot3(p, ap, first, 0, n, pap)
        for a in range(3):
            alpha[a] = rz[a] / pap[a] if pap[a] > 0.0 else 0.0
        _cg_update(v, p, r, z, ap, diag, alpha, first, n)
        _dot3(r, z, 0, 0, n, new_rz)
        for a in range(3):
            beta[a] = new_rz[a] / rz[a] if rz[a] > 0.0 else 0.0
            rz[a] = new_rz[a]
        _cg_direction(p, z, beta, free, first, n)
        it += 1
    return it


def implicit_update(x, v, first, start, near_end, nbr, coef, inertia, dt, free, guess,
                    tol=1e-6, max_iter=300):
    """Replace the tissue's velocities ``v[first:first+n]`` (m/s) by the backward-Euler solution.

    ``v`` holds v* on entry (after the explicit forces); ``inertia`` is the tissue's
    scaled masses (kg); ``free`` (n, 3) is 1.0 where a component is solved, 0.0 where it
    is held at its value; ``guess`` (n, 3) the expected correction (m/s), replaced by
    this step's. ``x`` is advanced by ``dt`` × the velocity correction, so that the
    positions follow the implicit velocities (symplectic Euler). Returns the CG
    iterations used.
    """
    n = len(start) - 1
    before = v[first:first + n].copy()
    iterations = _solve(v, first, start, near_end, nbr, coef, inertia, dt, free, guess, tol, max_iter)
    change = v[first:first + n] - before
    # the viscous forces are internal: along an axis with nothing held, remove the tiny net
    # impulse the CG residual leaves, so momentum is conserved to round-off
    total = float(inertia.sum())
    for a in range(3):
        if total > 0 and free[:, a].all():
            change[:, a] -= float(inertia @ change[:, a]) / total
    v[first:first + n] = before + change
    guess[:] = change
    x[first:first + n] += dt * guess
    return iterations
