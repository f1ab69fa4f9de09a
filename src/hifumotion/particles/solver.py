"""Time integration of a :class:`~hifumotion.particles.system.ParticleSystem`.

One step, in this order:

1. neighbours of every moving particle (cell-linked list, :mod:`.neighbours`);
2. fluid density and pressure (Eq. 10–11);
3. pair forces: pressure, viscosity, coupling and contact (Eq. 11, 12, 18);
4. tissue forces over the rest neighbourhoods: elastic, volume, hourglass and
   rheological viscosity (Eq. 12–16);
5. symplectic (semi-implicit) Euler: ``v += dt a`` then ``x += dt v`` for water
   and tissue — the impulses of Eq. 19–20 are this update;
6. rigid bodies: Eq. 17's force and torque → translation and rotation;
7. checks: a NaN, a particle leaving the domain or faster than the stability
   limit stops the run with :class:`SimulationDiverged` naming the step, the
   particles and the limit;
8. next step size: ``cfl`` × the smallest of the water's and the tissue's
   CFL limits (sound speed + fastest particle), the viscous limit, the
   contact-spring limit and the tissue's per-particle spring limit, capped at
   ``max_step_s``.

``mass_scaling`` s > 1 multiplies every particle's *inertia* (not its weight):
statics — gravity, buoyancy, pressure, elastic equilibrium — are unchanged,
waves travel √s slower and the step grows by √s. For quasi-static motion
(a slow push) this trades inertial transients for speed; the synthetic
experiment documents the tolerance it keeps. ``damping_per_s`` (γ) adds
``−γ v`` to every acceleration: dynamic relaxation to a static state, for
settling a scene and for the static validation cases; 0 in a real run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from hifumotion.errors import HifuError
from hifumotion.numerics import CFL, EXPLICIT_MASS_SCALING, EXPLICIT_MAX_STEP_S
from hifumotion.particles import elastic, fluid, viscosity
from hifumotion.particles.kernels import cubic_w
from hifumotion.particles.neighbours import CellGrid
from hifumotion.particles.system import ParticleSystem


def likely_cause(why: int, phase: str) -> str:
    """What most often makes a run fail this way (``why``: 1 not a number, 2 left the domain,
    3 too fast), for the particle kind that failed first."""
    if why == 2 and phase == "rigid":
        return ("likely cause: the bar was pushed through the tissue or out of the tank — a force too large for "
                "the tissue's stiffness, a bar that does not meet the tissue, or its tip outside the tank")
    if why == 2 and phase == "tissue":
        return ("likely cause: the tissue was squeezed out of the tank — a force too large for its stiffness or "
                "a tank too small for it")
    if why == 2:
        return "likely cause: water thrown out of the tank by a violent start — a smaller cfl, or a slower ramp"
    if phase == "tissue":
        return ("likely cause: a time step too long for the tissue's stiffness or contact — a smaller cfl or "
                "max_step_s, or a softer contact_coefficient")
    return "likely cause: a time step too long for the contacts — a smaller cfl or max_step_s, or softer coupling"


class SimulationDiverged(HifuError):
    """The simulation became unstable; the message names step, particles and limit."""


@dataclass(frozen=True)
class SolverSettings:
    """Integration settings.

    Attributes
    ----------
    cfl
        Safety factor on every step limit (dimensionless).
    max_step_s, min_step_s
        Bounds on the step (s); falling below ``min_step_s`` counts as divergence.
    mass_scaling
        Inertia multiplier s ≥ 1 for quasi-static runs (weights unchanged).
    damping_per_s
        Global velocity damping γ (1/s), for settling and static cases only.
    frozen_axes
        Velocity components held at zero for every particle (e.g. ``(2,)``: plane strain in x–y).
    neighbour_skin
        Verlet skin of the neighbour lists, as a fraction of h (rebuilt when stale).
    implicit_viscosity
        Integrate the tissue's rheological viscosity by backward Euler
        (:mod:`.viscosity`): no viscous step limit, so creep over seconds is affordable.
        ``False`` takes it explicitly with the viscous limit ρ Δx²/(4 μ).
    """

    cfl: float = CFL
    max_step_s: float = EXPLICIT_MAX_STEP_S
    min_step_s: float = 1e-9
    mass_scaling: float = EXPLICIT_MASS_SCALING
    damping_per_s: float = 0.0
    frozen_axes: tuple[int, ...] = ()
    neighbour_skin: float = 0.15
    implicit_viscosity: bool = True


@njit(cache=True, parallel=True)
def _integrate(x, v, force, mass, n, gravity, inertia_scale, damping, dt, held, held_velocity,
               frozen, speed2):
    """Symplectic Euler; components in ``held`` move at ``held_velocity`` (m/s) instead."""
    for i in prange(n):
        inv = 1.0 / (mass[i] * inertia_scale)
        s = 0.0
        for a in range(3):
            if held[i, a]:
                va = held_velocity[i, a]
            else:
                acc = force[i, a] * inv + gravity[a] / inertia_scale - damping * v[i, a]
                va = v[i, a] + dt * acc
                if frozen[a]:
                    va = 0.0
            v[i, a] = va
            x[i, a] += dt * va
            s += va * va
        speed2[i] = s


@njit(cache=True)
def _first_bad(x, v, n, lo, hi, speed_limit):
    """Index and reason (0 ok, 1 NaN, 2 outside, 3 too fast) of the first bad particle."""
    lim2 = speed_limit * speed_limit
    for i in range(n):
        ok = True
        for a in range(3):
            if not (math.isfinite(x[i, a]) and math.isfinite(v[i, a])):
                return i, 1
        for a in range(3):
            if x[i, a] < lo[a] or x[i, a] > hi[a]:
                ok = False
        if not ok:
            return i, 2
        if v[i, 0] ** 2 + v[i, 1] ** 2 + v[i, 2] ** 2 > lim2:
            return i, 3
    return -1, 0


class Solver:
    """Advances a :class:`ParticleSystem` in place, step by step (see the module docstring)."""

    def __init__(self, system: ParticleSystem, settings: SolverSettings = SolverSettings()):
        self.system = s = system
        self.settings = settings
        if settings.mass_scaling < 1.0:
            raise ValueError(f"mass_scaling must be >= 1, got {settings.mass_scaling}")
        h = s.support_m
        margin = 4 * h
        self.lo = s.domain_lo_m - margin
        self.hi = s.domain_hi_m + margin
        self.grid = CellGrid(self.lo, self.hi, h, skin=settings.neighbour_skin)
        self.table = None
        self.force = np.zeros_like(s.x)
        self.held = np.zeros((s.n_moving, 3), np.bool_)
        self.held_velocity = np.zeros((s.n_moving, 3))
        self.held[s.tissue_slice] = s.tissue_held
        self.held_velocity[s.tissue_slice] = s.tissue_held_velocity_m_s
        # the rigid particles are moved by their bodies (after _integrate)
        self.held[s.slice_of(2)] = True
        self.frozen = np.zeros(3, np.bool_)
        self.frozen[list(settings.frozen_axes)] = True
        self.speed2 = np.zeros(s.n_moving)
        self.excluded_water = 0                       # water particles parked after leaving the domain
        rho_t = s.tissue_density_kg_m3() or s.fluid.rest_density_kg_m3
        self.c_fluid = math.sqrt(s.fluid_stiffness_m2_s2) if s.n_fluid else 0.0
        self.c_tissue = s.tissue.p_wave_speed(rho_t) if s.n_tissue else 0.0
        self.lame = s.tissue.lame()
        # stiffest contact spring on a particle: K_c m_other max|d²W/dr²| per unit of its own
        # mass (Eq. 18 scales with both masses); |W''| peaks at r = 0: 96/(π h⁵)
        self.h_contact = min(s.coupling.contact_support_factor * s.spacing_m, h)
        w2 = 96.0 / (math.pi * self.h_contact ** 5)
        m = s.mass
        solid = s.phase != 0
        m_solid = float(m[solid].max()) if solid.any() else 0.0
        m_all = float(m.max()) if len(m) else 0.0
        solid_kinds = sum(1 for k in (s.n_tissue, s.n_wall) if k) + len(s.bodies)
        contact = s.contact_coefficient if solid_kinds > 1 else 0.0
        wetted = s.fluid_coefficient if s.n_fluid and (s.n_tissue or s.n_rigid) else 0.0
        walled = s.wall_coefficient if s.n_fluid and s.n_wall else 0.0
        omega2 = (contact * m_solid + wetted * m_all) * w2 + walled * m_all * w2 / 0.75 ** 5
        # a spring is stable for dt < 2/ω; the cfl factor leaves room for several contacts
        self.dt_contact = 2.0 / math.sqrt(omega2) if omega2 > 0 else math.inf
        self.m_light = float(m[: s.n_moving].min()) if s.n_moving else 1.0
        self.speed_limit = 2.0 * max(self.c_fluid, self.c_tissue, 1.0)
        self.mu_max = s.fluid.viscosity_pa_s if s.n_fluid else 0.0
        # pair forces only act between different phases or within the water
        self.needs_pairs = bool(s.n_fluid) or len(s.bodies) > 1 or sum(
            1 for k in (s.n_tissue, s.n_rigid, s.n_wall) if k) > 1
        self.tissue_volume = np.ascontiguousarray(s.rest_volume[s.tissue_slice])
        if s.rest is not None:
            self.pair_offsets, self.hourglass_coef = elastic.pair_constants(
                s.rest, s.tissue_rest, self.tissue_volume, s.tissue.youngs_modulus_pa, s.tissue.hourglass)
            self.gradient_reverse = np.ascontiguousarray(s.rest.gradient[s.rest.reverse])
            self.dt_tissue = self._tissue_stability_limit()
        else:
            self.dt_tissue = math.inf
        self.b_mat = np.zeros((s.n_tissue, 3, 3))
        self.viscous_coef = np.zeros(len(s.rest.neighbours) if s.rest is not None else 0)
        self.tissue_mu_max = 0.0                     # largest rheological μ of the last step (Pa·s)
        self.viscous_iterations = 0                  # CG iterations of the last implicit solve
        tissue = s.tissue_slice
        self.tissue_inertia = np.ascontiguousarray(s.mass[tissue] * settings.mass_scaling)
        self.tissue_free = (~self.held[tissue]).astype(np.float64)
        self.viscous_correction = np.zeros((s.n_tissue, 3))   # last implicit change of v (m/s)
        self.pressure = np.zeros(len(s.x))          # water's own, solids' extrapolated (Pa)
        self.volume = s.rest_volume.copy()           # m/ρ for water, rest volume for solids (m³)
        self.work = np.zeros((s.n_tissue, 4, 3, 3))
        self.rigid_slice = s.slice_of(2)
        # solids skip their own phase in the pair lists (their internal forces are elsewhere);
        # each rigid body is its own group, so two bars would still touch
        self.group = np.where(s.phase == 0, -1, s.phase.astype(np.int64) * 1_000_000)
        for k, b in enumerate(s.bodies):
            self.group[b.first:b.first + b.count] += k
        self.dt = self._step_size(0.0)

    def _tissue_stability_limit(self) -> float:
        """2/ω_max of the tissue's springs (s), particle by particle.

        A particle's elastic stiffness is about (λ + 2G) v Σ|d|² over the gradient
        weights of its own and its neighbours' fits (a Gershgorin bound), plus its
        hourglass springs (2 |coef| per pair). Where the MLS fit is poorly conditioned
        (corners, thin parts) this exceeds the lattice estimate Δx/c_P by up to 2×,
        which is what destabilised a thin beam before this limit was added.
        """
        s = self.system
        r = s.rest
        rows = np.repeat(np.arange(s.n_tissue), np.diff(r.start))
        g2 = (r.gradient ** 2).sum(1)
        lam, g = self.lame
        modulus = lam + 2 * g + s.tissue.volume_stiffness_pa
        vol = self.tissue_volume
        elastic_k = modulus * (vol * np.bincount(rows, g2, s.n_tissue)
                               + np.bincount(r.neighbours, g2 * vol[rows], s.n_tissue))
        near = np.arange(len(rows)) < r.near_end[rows]
        hourglass_k = np.bincount(rows[near], 2 * np.abs(self.hourglass_coef[near]), s.n_tissue)
        omega2 = (elastic_k + hourglass_k) / s.mass[s.tissue_slice]
        return 2.0 / math.sqrt(float(omega2.max())) if omega2.max() > 0 else math.inf

    # -- forces -----------------------------------------------------------
    def compute_forces(self) -> np.ndarray:
        """Interaction forces (N) on every moving particle at the current state."""
        s = self.system
        n = s.n_moving
        self.force[:] = 0.0
        if not self.needs_pairs:
            return self._tissue_forces()
        if self.table is None or self.grid.stale(s.x[:n]):
            self.table = self.grid.query(s.x, 0, n, self.group)
        table = self.table
        if s.n_fluid:
            fluid.fluid_density(s.x, s.mass, s.rest_volume, s.phase, s.n_fluid, table.indices,
                                table.counts, s.support_m, s.fluid.rest_density_kg_m3,
                                s.fluid_stiffness_m2_s2, s.density, self.pressure, self.volume)
            fluid.solid_pressure(s.x, s.n_fluid, table.indices, table.counts, s.support_m,
                                 s.density, self.pressure, s.gravity_m_s2)
            s.pressure[:] = self.pressure[: s.n_fluid]
        c = s.coupling
        fluid.pair_forces(
            s.x, s.v, s.mass, self.volume, s.phase, self.pressure, 0, table.indices, table.counts,
            s.support_m, self.h_contact, s.fluid.viscosity_pa_s, s.fluid_coefficient, s.wall_coefficient,
            s.contact_coefficient,
            c.friction, c.slip_speed_m_s, 0.25 * self.m_light * self.settings.mass_scaling / self.dt,
            self.force)
        return self._tissue_forces()

    def _tissue_forces(self) -> np.ndarray:
        s = self.system
        mu = s.fluid.viscosity_pa_s if s.n_fluid else 0.0
        if s.n_tissue and s.rest is not None:
            t = s.tissue
            r = s.rest
            first = s.tissue_slice.start
            b_mat = self.b_mat
            elastic.stress_pass(s.x, s.tissue_rest, first, r.start, r.neighbours, r.gradient,
                                self.tissue_volume, self.lame[0], self.lame[1],
                                t.volume_stiffness_pa, t.corotated, s.deform, b_mat, s.strain,
                                self.work)
            implicit = self.settings.implicit_viscosity and t.beta1 != 0.0
            if implicit:  # coefficients from the start-of-step state; forces in step()
                self.tissue_mu_max = viscosity.pair_coefficients(
                    s.x, s.v, first, r.start, r.near_end, r.neighbours, self.tissue_volume, r.near_m,
                    t.beta1, t.beta2, t.mu_max_pa_s, t.rate_floor_per_s, self.viscous_coef)
            mu_t = elastic.force_pass(s.x, s.v, first, r.start, r.near_end, r.neighbours, self.pair_offsets,
                                      self.hourglass_coef, r.gradient, self.gradient_reverse,
                                      self.tissue_volume,
                                      s.deform, b_mat, r.near_m, t.hourglass != 0.0,
                                      0.0 if implicit else t.beta1,
                                      t.beta2, t.mu_max_pa_s, t.rate_floor_per_s, self.force)
            mu = max(mu, mu_t)
        self.mu_max = mu
        return self.force[: s.n_moving]

    # -- step ---------------------------------------------------------------
    def _step_size(self, v_max: float) -> float:
        s = self.system
        st = self.settings
        sc = math.sqrt(st.mass_scaling)
        limits = [st.max_step_s]
        dx = s.spacing_m
        if s.n_fluid:
            limits.append(dx / (self.c_fluid / sc + v_max))
        if s.n_tissue:
            limits.append(dx / (self.c_tissue / sc + v_max))  # advection; waves: dt_tissue
        rho_min = min(s.fluid.rest_density_kg_m3, s.tissue_density_kg_m3() or math.inf)
        if self.mu_max > 0:
            limits.append(0.25 * rho_min * st.mass_scaling * dx * dx / self.mu_max)
        limits.append(self.dt_contact * sc)
        limits.append(self.dt_tissue * sc)
        if v_max == 0 and not (s.n_fluid or s.n_tissue):
            limits.append(dx / max(self.speed_limit, 1.0))
        return min(st.cfl * min(limits[1:]), st.max_step_s)

    def step(self) -> float:
        """Advance one step; returns its size (s)."""
        s = self.system
        st = self.settings
        dt = self.dt
        n = s.n_moving
        self.compute_forces()
        rigid = self.rigid_slice
        _integrate(s.x, s.v, self.force, s.mass, n, s.gravity_m_s2, st.mass_scaling,
                   st.damping_per_s, dt, self.held, self.held_velocity, self.frozen, self.speed2)
        if st.implicit_viscosity and s.tissue.beta1 != 0.0 and s.rest is not None and s.n_tissue:
            r = s.rest
            tissue = s.tissue_slice
            self.viscous_iterations = viscosity.implicit_update(
                s.x, s.v, tissue.start, r.start, r.near_end, r.neighbours, self.viscous_coef,
                self.tissue_inertia, dt, self.tissue_free, self.viscous_correction)
            self.speed2[tissue] = (s.v[tissue] ** 2).sum(1)
        for body in s.bodies:
            sl = slice(body.first, body.first + body.count)
            body.step(self.force[sl], s.gravity_m_s2, s.time_s, dt, st.mass_scaling)
            if st.damping_per_s and body.prescribed_velocity_m_s is None:
                body.velocity_m_s *= math.exp(-st.damping_per_s * dt)
                body.angular_momentum *= math.exp(-st.damping_per_s * dt)
            xb, vb = body.particle_states()
            s.x[sl] = xb
            s.v[sl] = vb
        if s.n_rigid:
            self.speed2[rigid] = (s.v[rigid] ** 2).sum(1)
        s.time_s += dt
        s.step += 1
        self._check()
        v_max = math.sqrt(float(self.speed2.max())) if n else 0.0
        self.dt = max(self._step_size(v_max), 0.0)
        if self.dt < st.min_step_s:
            raise SimulationDiverged(
                f"step {s.step} (t = {s.time_s:.6g} s): time step fell to {self.dt:.3g} s, below "
                f"min_step_s = {st.min_step_s:g} (viscosity {self.mu_max:.3g} Pa·s, "
                f"max speed {v_max:.3g} m/s)")
        return dt

    def _check(self) -> None:
        s = self.system
        i, why = _first_bad(s.x, s.v, s.n_moving, self.lo, self.hi, self.speed_limit)
        if why == 2 and s.phase[i] == 0:
            self._exclude_spray()
            i, why = _first_bad(s.x, s.v, s.n_moving, self.lo, self.hi, self.speed_limit)
        if why == 0:
            return
        from hifumotion.particles._numba import PHASE_NAMES

        kind = PHASE_NAMES[int(s.phase[i])]
        if why == 1:
            bad = np.flatnonzero(~np.all(np.isfinite(s.x[: s.n_moving]) & np.isfinite(s.v[: s.n_moving]), axis=1))
            reason = "position or velocity is not a number"
        elif why == 2:
            x = s.x[: s.n_moving]
            excess = np.maximum(self.lo - x, x - self.hi).max(axis=1)
            bad = np.flatnonzero(excess > 0)
            bad = bad[np.argsort(-excess[bad])]  # furthest out first
            reason = (f"left the domain [{', '.join(f'{v:.4g}' for v in self.lo)}] – "
                      f"[{', '.join(f'{v:.4g}' for v in self.hi)}] m")
        else:
            bad = np.flatnonzero(self.speed2 > self.speed_limit ** 2)
            bad = bad[np.argsort(-self.speed2[bad])]  # fastest first
            reason = (f"moves faster than {self.speed_limit:.3g} m/s (twice the fastest sound speed: "
                      "energy blow-up)")
        shown = ", ".join(str(b) for b in bad[:8]) + (" …" if len(bad) > 8 else "")
        worst = PHASE_NAMES[int(s.phase[bad[0]])] if len(bad) else kind
        raise SimulationDiverged(
            f"step {s.step} (t = {s.time_s:.6g} s): {len(bad)} particle(s) [{shown}], worst a "
            f"{worst} particle, {reason}; {likely_cause(why, worst)}")

    def _exclude_spray(self) -> None:
        """Park the water particles that left the domain (as DualSPHysics excludes them).

        A drop squeezed out from under the tissue can fly off; under mass scaling its
        weight decelerates it √s-fold slower, so it may leave the tank. It is parked
        where it left (clipped to the domain), at rest and held there, far from the
        rest of the water; ``excluded_water`` counts them (reported by the run).
        """
        s = self.system
        xf = s.x[: s.n_fluid]
        out = np.flatnonzero(np.any((xf < self.lo) | (xf > self.hi), axis=1))
        xf[out] = np.clip(xf[out], self.lo, self.hi)
        s.v[out] = 0.0
        self.held[out] = True
        self.held_velocity[out] = 0.0
        self.speed2[out] = 0.0
        self.excluded_water += len(out)

    def run(self, duration_s: float, callback=None, every_s: float | None = None) -> None:
        """Advance by ``duration_s``; ``callback(solver)`` every ``every_s`` of simulated time."""
        end = self.system.time_s + duration_s
        next_cb = self.system.time_s + (every_s or math.inf)
        while self.system.time_s < end - 1e-15:
            remaining = end - self.system.time_s
            if self.dt > remaining:
                self.dt = remaining
            if callback is not None and self.dt > next_cb - self.system.time_s > 0:
                self.dt = next_cb - self.system.time_s
            self.step()
            if callback is not None and self.system.time_s >= next_cb - 1e-12:
                callback(self)
                next_cb += every_s


@njit(cache=True, parallel=True)
def smoothed_pressure(x, mass, density, pressure, n_fluid, table, counts, h):
    """Kernel-averaged fluid pressure (Pa): Σ p_j v_j W / Σ v_j W, with the particle itself."""
    out = np.empty(n_fluid)
    w0 = cubic_w(0.0, h)
    for i in prange(n_fluid):
        num = pressure[i] * mass[i] / density[i] * w0
        den = mass[i] / density[i] * w0
        for k in range(counts[i]):
            j = table[i, k]
            if j >= n_fluid:
                continue
            r = math.sqrt((x[j, 0] - x[i, 0]) ** 2 + (x[j, 1] - x[i, 1]) ** 2 + (x[j, 2] - x[i, 2]) ** 2)
            w = cubic_w(r, h) * mass[j] / density[j]
            num += pressure[j] * w
            den += w
        out[i] = num / den
    return out
