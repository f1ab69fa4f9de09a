"""SPH fluid and multiphase coupling (the paper's Eq. 8–12 and 18–20), SI units.

Per fluid particle i, over the current neighbours j within the support radius h:

* density by summation (Eq. 10): ``ρ_i = m_i W(0) + Σ_j m̃_j W_ij``, where
  m̃_j is j's mass for a fluid neighbour and ``ρ0 v_j`` (its rest volume filled
  with water) for a solid one (tissue, bar or wall) — Akinci et al. 2012's
  boundary contribution, so water at rest next to a wall or the tissue is at ρ0;
* equation of state ``p_i = K (ρ_i − ρ0)`` (Eq. 11's text; K = c² in m²/s²), clamped at 0 so the
  density deficit of the free surface does not pull particles together;
* pressure force (Eq. 11): ``f_i = −v_i Σ_j v_j (p_i + p_j) ∇W_ij``, v = m/ρ.
  Two corrections to the printed Eq. 11, both in docs/decisions.md: the minus
  of −∇p is restored, and the arithmetic mean (p_i + p_j)/2 is doubled —
  over a full neighbourhood Σ v_j p_i ∇W_ij vanishes, so the mean would give
  only ½∇p (a fluid compressing twice as much as K says, and inconsistent
  with the walls). With the factor this is the standard symmetric SPH
  pressure force (Monaghan 1992 for equal densities).
  A solid neighbour (wall, tissue or bar particle w) carries the pressure
  extrapolated from the water around it (Adami, Hu & Adams 2012):
  ``p_w = (Σ_f p_f W_wf + g · Σ_f ρ_f (x_w − x_f) W_wf) / Σ_f W_wf`` — the
  hydrostatic term keeps the water from sinking into the floor — so water
  pushes on the tissue, the bar and the walls: buoyancy and the tank. (Adami
  also subtracts the wall's acceleration; it is neglected for slow motion);
* fluid viscosity (Eq. 12): ``f_i = v_i Σ_j μ v_j (v_j − v_i) ∇²W_visc``;

and between particles of different phases (fluid–tissue, fluid–bar,
tissue–bar, tissue–wall, bar–wall) the coupling force of Eq. 18,
``f = −K_c m_a m_b ∇W_ab``, a repulsion along the line between them. Its
kernel has a support of one particle spacing (``contact_support_factor``), not
h: with h, particles resting one spacing apart — a tissue lying on the floor —
would already push each other with most of the peak force, so the tissue
would hover a spacing above the floor and jump at the first step. Eq. 19–20
apply it as equal and opposite impulses (the paper prints both with a minus,
which would not conserve momentum; the reaction's sign is restored). Solid
contacts (not fluid) also carry a regularised Coulomb friction
``|f_t| ≤ μ_f |f_n|`` against the relative sliding velocity.

Every pair term is written so that the force i feels from j is exactly the
negative of the one j feels from i, whichever particle's loop computes it:
momentum is conserved to round-off. Forces land in a gathered per-particle
array (no scatter, no atomics), so the loops run in parallel.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from hifumotion.particles._numba import FLUID, RIGID, WALL
from hifumotion.particles.kernels import cubic_dw, cubic_w, viscosity_laplacian


@njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
def fluid_density(x, mass, rest_volume, phase, n_fluid, table, counts, h, rho0, stiffness,
                  density, pressure, volume):
    """Summation density (Eq. 10, kg/m³), pressure (Pa) and volume m/ρ (m³) of the water.

    Fluid particles are 0 … n_fluid − 1; ``pressure`` and ``volume`` are per particle
    (their solid entries are left alone).
    """
    w0 = cubic_w(0.0, h)
    h2 = h * h
    for i in prange(n_fluid):
        rho = mass[i] * w0
        for k in range(counts[i]):
            j = table[i, k]
            d0 = x[j, 0] - x[i, 0]
            d1 = x[j, 1] - x[i, 1]
            d2 = x[j, 2] - x[i, 2]
            rr = d0 * d0 + d1 * d1 + d2 * d2
            if rr >= h2:
                continue
            wij = cubic_w(math.sqrt(rr), h)
            if phase[j] == FLUID:
                rho += mass[j] * wij
            else:
                rho += rho0 * rest_volume[j] * wij
        density[i] = rho
        volume[i] = mass[i] / rho
        p = stiffness * (rho - rho0)
        pressure[i] = p if p > 0.0 else 0.0


@njit(cache=True)
def solid_pressure(x, n_fluid, table, counts, h, density, pressure, gravity):
    """Pressure (Pa) of every solid particle next to water (Adami et al. 2012).

    ``pressure`` has one entry per particle: the water's are read, the solids'
    written (0 without water around). Serial: it scatters from the fluid rows.
    """
    out = pressure
    n = out.shape[0]
    h2 = h * h
    num = np.zeros(n)
    den = np.zeros(n)
    for i in range(n_fluid):
        for k in range(counts[i]):
            j = table[i, k]
            if j < n_fluid:
                continue
            r0 = x[j, 0] - x[i, 0]
            r1 = x[j, 1] - x[i, 1]
            r2 = x[j, 2] - x[i, 2]
            rr = r0 * r0 + r1 * r1 + r2 * r2
            if rr >= h2:
                continue
            wij = cubic_w(math.sqrt(rr), h)
            num[j] += (pressure[i] + density[i] * (gravity[0] * r0 + gravity[1] * r1
                                                   + gravity[2] * r2)) * wij
            den[j] += wij
    for j in range(n_fluid, n):
        if den[j] > 0.0:
            p = num[j] / den[j]
            out[j] = p if p > 0.0 else 0.0
        else:
            out[j] = 0.0


@njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
def pair_forces(x, v, mass, volume, phase, pressure, first, table, counts, h, h_contact, mu_fluid,
                k_fluid, k_wall, k_contact, friction, slip_speed, friction_damping_max, force):
    """Pressure (Eq. 11), viscosity (Eq. 12) and coupling (Eq. 18) forces (N).

    Rows of ``table`` are the neighbours of particles ``first, first + 1, …``; the
    coupling of Eq. 18 uses the kernel with support ``h_contact`` (≤ h), with
    ``k_fluid`` between water and solids, ``k_wall`` between water and the tank and
    ``k_contact`` between solids; the
    forces on them are *added* to ``force``. ``volume`` (m³) is m/ρ for water and the
    rest volume for solids; ``pressure`` (Pa) is the water's own or, for a solid, the
    one extrapolated by :func:`solid_pressure`. Friction's viscous regularisation is
    capped at ``friction_damping_max`` (N·s/m), the stiffest the time step can take.
    Returns the largest contact force magnitude seen (N).
    """
    n = counts.shape[0]
    biggest = np.zeros(n)
    h2 = h * h
    for row in prange(n):
        i = first + row
        pi_phase = phase[i]
        i_fluid = pi_phase == FLUID
        vol_i = volume[i]
        p_i = pressure[i]
        xi0 = x[i, 0]
        xi1 = x[i, 1]
        xi2 = x[i, 2]
        fx = 0.0
        fy = 0.0
        fz = 0.0
        big = 0.0
        for k in range(counts[row]):
            j = table[row, k]
            r0 = x[j, 0] - xi0
            r1 = x[j, 1] - xi1
            r2 = x[j, 2] - xi2
            rr = r0 * r0 + r1 * r1 + r2 * r2
            if rr >= h2 or rr <= 0.0:
                continue
            r = math.sqrt(rr)
            pj_phase = phase[j]
            j_fluid = pj_phase == FLUID
            dw = cubic_dw(r, h)
            if i_fluid or j_fluid:
                # −v_i v_j (p_i + p_j) ∇_i W, ∇_i W = −dW/dr · r_vec / r (r_vec = x_j − x_i);
                # (p_i + p_j) is twice Eq. 11's arithmetic mean, see the module docstring
                sc = vol_i * volume[j] * (p_i + pressure[j]) * dw / r
                fx += sc * r0
                fy += sc * r1
                fz += sc * r2
                if i_fluid and j_fluid:
                    if mu_fluid > 0.0:
                        t = mu_fluid * vol_i * volume[j] * viscosity_laplacian(r, h)
                        fx += t * (v[j, 0] - v[i, 0])
                        fy += t * (v[j, 1] - v[i, 1])
                        fz += t * (v[j, 2] - v[i, 2])
                    continue
                # water and tank: pressure, and a penalty that only acts closer than ¾ of a
                # spacing (untouched by hydrostatic compression, ≪ 25 %), so that water squeezed
                # under a solid cannot be pushed through the floor
                if pi_phase == WALL or pj_phase == WALL:
                    kc = k_wall
                    hc = 0.75 * h_contact
                else:
                    kc = k_fluid
                    hc = h_contact
            elif pi_phase == pj_phase and pi_phase != RIGID:
                continue
            else:
                kc = k_contact
                hc = h_contact
            if kc == 0.0 or r >= hc:
                continue
            # Eq. 18: f_i = −K_c m_i m_j ∇W(x_i − x_j) = K_c m_i m_j dW/dr · r_vec / r;
            # dW/dr < 0, so the force points away from j (a repulsion)
            c = kc * mass[i] * mass[j] * cubic_dw(r, hc) / r
            fx += c * r0
            fy += c * r1
            fz += c * r2
            fn = -c * r
            if fn > big:
                big = fn
            if friction > 0.0 and not i_fluid and not j_fluid:
                ux = r0 / r
                uy = r1 / r
                uz = r2 / r
                w0 = v[j, 0] - v[i, 0]
                w1 = v[j, 1] - v[i, 1]
                w2 = v[j, 2] - v[i, 2]
                dn = w0 * ux + w1 * uy + w2 * uz
                t0 = w0 - dn * ux
                t1 = w1 - dn * uy
                t2 = w2 - dn * uz
                vt = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
                scale = min(friction * fn / max(vt, slip_speed), friction_damping_max)
                fx += scale * t0
                fy += scale * t1
                fz += scale * t2
        force[i, 0] += fx
        force[i, 1] += fy
        force[i, 2] += fz
        biggest[row] = big
    return biggest.max() if n else 0.0
