"""The twin's physics: the tissue creeping under the bar in time, by quadratic finite elements.

The synthetic experiment's truth must not share the fitted model's errors
(:mod:`hifumotion.creep`: trilinear voxels, lagged viscosity, node-on-surface contact on
a lattice). This solver shares its *physics* — the same constitutive law and the same
contacts — and none of its discretisation:

* **Space**: ten-node (P2) tetrahedra on a TetGen quality mesh of the tissue's true
  surface (:mod:`._p2`), full Gauss integration of order 4 (mass) and of order 2 for the
  strain terms — no selective integration, no voxels, no lattice.
* **Material** (Eq. 12–16 in continuum form, as the fitted model's docstring states it):
  small-strain isotropic elasticity (E, ν) plus the Kelvin–Voigt viscous stress
  σ_v = 2 μ ε̇, μ = min(β1 max(γ̇, floor)^β2, μ_max), γ̇ = √(2 dev ε̇ : dev ε̇) at every
  quadrature point; μ is iterated to consistency within each step (the fitted model lags
  it one step).
* **Time**: variable-step BDF2 (second order; the fitted model is first order), the step
  chosen by the local error estimated against a quadratic predictor (Milne) ≤
  ``tolerance_mm``, restarted by a backward-Euler step at each kink of the schedule; the
  consistent mass keeps rigid modes well posed and weighs nothing
  measurable beside the creep.
* **Contacts** (Coulomb, μ_f): the floor y = 0 and the bar's flat end, a rigid disc that
  translates along its axis only, its advance δ balancing the force schedule F(t).
  Contact points (P2 surface nodes) carry their normal constraint and either stick or
  slip in their tangent plane; the active set grows, releases (a pulling contact),
  slips (|R_t| > μ_f N) and sticks again (a slip that reverses), and each round solves
  the constrained system *affinely in δ* (two right-hand sides), δ from the balance.
* **Water**: buoyancy on the submerged part, ``(ρ − ρ_w) g`` below the water line,
  ``ρ g`` above it, per quadrature point.

The tank's side walls are not modelled; :attr:`CreepFESolution.stats` reports how close
the tissue came to them is the caller's business (the twin checks it).

Units: mm, s, N at the interface; SI inside.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from hifumotion.numerics import TRUTH_TOLERANCE_MM
from hifumotion.physical import STANDARD_GRAVITY_M_S2, TISSUE_DENSITY_KG_M3, WATER_DENSITY_KG_M3
from hifumotion.errors import InputError
from hifumotion.rheology import MU_MAX_PA_S
from hifumotion.reference._p2 import MM, P2Mesh, p2_mesh

FLOOR, BAR = 0, 1


@dataclass(frozen=True)
class CreepingTissue:
    """The problem (mm, Pa, Pa·s^(1+β2), N, kg/m³; ``force_n(t)`` in N at t in s).

    ``breakpoints_s``: the times where the force schedule bends (steps land on them).
    ``water_line_mm``: the water surface's height (None: dry).
    ``travel_mm(t)``: travel control — the bar driven that far (mm) along its axis from where
    it rests on the settled tissue, ``force_n`` then not read (its force is a result); only
    the finite-strain truth drives a bar (:mod:`.finite_strain_push`).
    ``edge_radius_mm``: the rounding of the edge of the bar's end (mm); only the finite-strain
    truth, whose bar is a solid, has one (the small-strain truth's is its end's disc).
    """

    vertices_mm: np.ndarray
    faces: np.ndarray
    youngs_modulus_pa: float
    poisson_ratio: float
    beta1: float
    beta2: float
    rate_floor_per_s: float
    tip_mm: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius_mm: float
    force_n: Callable[[float], float]
    breakpoints_s: tuple[float, ...] = ()
    density_kg_m3: float = TISSUE_DENSITY_KG_M3
    water_density_kg_m3: float = WATER_DENSITY_KG_M3
    water_line_mm: float | None = None
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2
    floor_friction: float = 0.5
    bar_friction: float = 0.5
    mu_max_pa_s: float = MU_MAX_PA_S
    max_volume_mm3: float = 2.0
    travel_mm: Callable[[float], float] | None = None
    edge_radius_mm: float = 0.5


@dataclass
class CreepFESettings:
    """Numerical settings: the step's local error (mm), the first and largest steps (s),
    the rounds of contact/viscosity iteration per step and their relative tolerance, and the
    tangential displacement (mm) up to which a contact's friction is elastic (Coulomb's law regularised)."""

    tolerance_mm: float = TRUTH_TOLERANCE_MM
    first_step_s: float = 2e-3
    max_step_s: float = 0.25
    max_rounds: int = 60
    rtol: float = 1e-3
    stick_mm: float = 1e-3


@dataclass
class CreepFESolution:
    """The creep at the requested times (frame 0: settled under gravity, the bar touching).

    ``displacement_m`` is ``(frames, dofs)`` from the unloaded rest shape; ``advance_mm``
    the bar's advance since frame 0; ``force_n`` the force the tissue took.
    """

    times_s: np.ndarray
    displacement_m: np.ndarray
    advance_mm: np.ndarray
    force_n: np.ndarray
    stats: dict
    p2: P2Mesh = field(repr=False)

    def displacement_at(self, points_mm: np.ndarray) -> np.ndarray:
        """``(frames, n, 3)`` displacement (mm) of rest points ``points_mm`` (P2 interpolation;
        a point outside the mesh takes its nearest P2 node's)."""
        probes, _ = self.p2.probes(points_mm)
        n = len(np.asarray(points_mm).reshape(-1, 3))
        out = (probes @ self.displacement_m.T) / MM          # (3n, frames)
        return out.reshape(3, n, -1).transpose(2, 1, 0)


class _Contacts:
    """The active set of the surface points: where each touches (−1 none, FLOOR, BAR), its
    normal force N (N), its friction spring (N/m) and anchor (the displacement, m, its
    friction pulls it back to), and whether it left a contact this step."""

    def __init__(self, n_points: int):
        self.where = np.full(n_points, -1)
        self.pressure = np.zeros(n_points)
        self.spring = np.zeros(n_points)
        self.anchor = np.zeros((n_points, 3))
        self.left = np.zeros(n_points, bool)

    def copy(self) -> "_Contacts":
        other = _Contacts(0)
        for name in ("where", "pressure", "spring", "anchor", "left"):
            setattr(other, name, getattr(self, name).copy())
        return other


def _tangents(normal: np.ndarray) -> np.ndarray:
    """A 3 × 3 orthonormal frame whose first row is ``normal``."""
    n = normal / np.linalg.norm(normal)
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1)
    return np.stack([n, t1, np.cross(n, t1)])


class _Solver:
    def __init__(self, problem: CreepingTissue, settings: CreepFESettings):
        import skfem
        from skfem.helpers import ddot, dot, sym_grad, trace

        p = self.problem = problem
        self.settings = settings
        if not p.youngs_modulus_pa > 0 or not -1.0 < p.poisson_ratio < 0.5:
            raise InputError(f"need E > 0 and −1 < ν < 0.5, got E = {p.youngs_modulus_pa}, ν = {p.poisson_ratio}",
                             "tissue")
        self.p2 = p2_mesh(p.vertices_mm, p.faces, p.max_volume_mm3)
        basis = self.basis = self.p2.basis
        # the strain terms at order 2 (exact for P2's linear strains), the mass at the mesh's order
        self.strain_basis = skfem.Basis(basis.mesh, basis.elem, intorder=2)
        e, nu = p.youngs_modulus_pa, p.poisson_ratio
        lam, g = e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))

        @skfem.BilinearForm
        def elastic(u, v, w):
            eu, ev = sym_grad(u), sym_grad(v)
            return lam * trace(eu) * trace(ev) + 2.0 * g * ddot(eu, ev)

        @skfem.BilinearForm
        def mass(u, v, w):
            return p.density_kg_m3 * dot(u, v)

        water_line = None if p.water_line_mm is None else p.water_line_mm * MM

        @skfem.LinearForm
        def weight(v, w):
            rho = p.density_kg_m3 - (0.0 if water_line is None else p.water_density_kg_m3 * (w.x[1] < water_line))
            return -rho * p.gravity_m_s2 * v[1]

        self.stiffness = skfem.asm(elastic, self.strain_basis).tocsr()
        self.mass = skfem.asm(mass, basis).tocsr()
        self.load = skfem.asm(weight, basis)
        self.regular = 1e-9 * float(self.stiffness.diagonal().mean())
        self.rest = self.p2.points_m
        self.surface = np.flatnonzero(self.p2.on_surface)
        self.axis = np.asarray(p.axis, float) / np.linalg.norm(p.axis)
        self.bar_frame = _tangents(self.axis)
        self.floor_frame = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
        self.tip = np.asarray(p.tip_mm, float) * MM
        self.size = float(np.ptp(self.rest, axis=0).max())
        self.gap_tol = 1e-7 * self.size
        self.contacts = _Contacts(len(self.rest))
        self.advance = 0.0
        self.pushing = False
        self.stats = {"steps": 0, "rejected": 0, "rounds": 0, "solves": 0, "unsettled_steps": 0,
                      "max_penetration_mm": 0.0}

    # -- geometry ---------------------------------------------------------------------
    def frames(self, points: np.ndarray) -> np.ndarray:
        where = self.contacts.where[points]
        return np.where((where == BAR)[:, None, None], self.bar_frame[None], self.floor_frame[None])

    def normal_target(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The prescribed normal displacement c + δ·k of contact points (floor: y = 0; bar: on its face)."""
        where = self.contacts.where[points]
        rel = self.rest[points] - self.tip
        const = np.where(where == BAR, -(rel @ self.axis), -self.rest[points, 1])
        return const, (where == BAR).astype(float)

    def strain_rate(self, velocity: np.ndarray) -> np.ndarray:
        """γ̇ = √(2 dev ε̇ : dev ε̇) (1/s) at the strain quadrature points, (elements, points)."""
        from skfem.helpers import sym_grad

        eps = sym_grad(self.strain_basis.interpolate(velocity))
        tr = (eps[0, 0] + eps[1, 1] + eps[2, 2]) / 3.0
        dev2 = sum(((eps[i, j] - (tr if i == j else 0.0)) ** 2) for i in range(3) for j in range(3))
        return np.sqrt(2.0 * dev2)

    def viscosity(self, rate: np.ndarray) -> np.ndarray:
        p = self.problem
        from hifumotion.rheology import viscosity_pa_s

        return viscosity_pa_s(rate, p.beta1, p.beta2, p.rate_floor_per_s, p.mu_max_pa_s)

    # -- one constrained solve ----------------------------------------------------------
    def reduction(self):
        """``u = T q + g + δ s`` for the current contact set: a contact point's normal
        displacement is prescribed, its tangential ones are free (friction is a force)."""
        cs = self.contacts
        n = len(self.rest)
        contact = np.flatnonzero(cs.where >= 0)
        free = np.setdiff1d(np.arange(n), contact)
        dof = self.p2.dof_xyz
        rows = [dof[free].ravel()]
        cols = [np.arange(3 * len(free))]
        vals = [np.ones(3 * len(free))]
        ncol = 3 * len(free)
        g = np.zeros(self.p2.dofs)
        s = np.zeros(self.p2.dofs)
        if len(contact):
            fr = self.frames(contact)
            const, coef = self.normal_target(contact)
            np.add.at(g, dof[contact].ravel(), (const[:, None] * fr[:, 0]).ravel())
            np.add.at(s, dof[contact].ravel(), (coef[:, None] * fr[:, 0]).ravel())
            for k in (1, 2):
                rows.append(dof[contact].ravel())
                cols.append(np.repeat(ncol + np.arange(len(contact)), 3))
                vals.append(fr[:, k].ravel())
                ncol += len(contact)
        t = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(self.p2.dofs, ncol))
        return t, g, s

    def friction(self) -> tuple[sp.csr_matrix, np.ndarray]:
        """Coulomb friction as springs to the anchors, ``k_i P_t (u − anchor_i)``: the matrix (N/m)
        and its right-hand side (N) for the current springs."""
        cs = self.contacts
        contact = np.flatnonzero((cs.where >= 0) & (cs.spring > 0))
        n = self.p2.dofs
        if len(contact) == 0:
            return sp.csr_matrix((n, n)), np.zeros(n)
        fr = self.frames(contact)
        proj = np.einsum("nak,nal->nkl", fr[:, 1:], fr[:, 1:]) * cs.spring[contact, None, None]
        dof = self.p2.dof_xyz[contact]
        rows = np.repeat(dof, 3, axis=1).ravel()
        cols = np.tile(dof, (1, 3)).ravel()
        matrix = sp.csr_matrix((proj.ravel(), (rows, cols)), shape=(n, n))
        anchors = np.zeros(n)
        anchors[dof.ravel()] = cs.anchor[contact].ravel()
        return matrix, matrix @ anchors

    def solve(self, a: sp.csr_matrix, b: np.ndarray, force: float | None):
        """u and the contact reactions R = A u − b for the current set; δ from the force balance
        (``force`` None: the bar holds its advance).

        A round's matrix differs from the last one's by μ only while the contact set holds:
        the last factorisation then preconditions conjugate gradients to 10⁻¹¹ (a direct
        solve's accuracy); a new set, or CG that stalls, factorises afresh."""
        from hifumotion.creep.linear import Factor, preconditioned_cg

        key = self.contacts.where.tobytes()
        if key != getattr(self, "_set_key", None):
            self._reduction = self.reduction()
            self._set_key = key
            self._guess = None
            if getattr(self, "_factor", None) is not None:
                self._factor.release()
            self._factor = None
        t, g, s = self._reduction
        reduced = (t.T @ a @ t).tocsr()
        rhs = np.stack([t.T @ (b - a @ g), -(t.T @ (a @ s))], axis=1)
        q = None
        if self._factor is not None and self._guess is not None:
            q = np.empty_like(rhs)
            for k in range(2):
                q[:, k], its, ok = preconditioned_cg(lambda x: reduced @ x, rhs[:, k], self._factor,
                                                     self._guess[:, k], 1e-11, 40)
                self.stats["cg_iterations"] = self.stats.get("cg_iterations", 0) + its
                if not ok:
                    q = None
                    break
        if q is None:
            if self._factor is not None:
                self._factor.release()
            self._factor = Factor(reduced)
            self.stats["factorisations"] = self.stats.get("factorisations", 0) + 1
            q = self._factor.solve(rhs)
        self._guess = q
        self.stats["solves"] += 1
        u0, u1 = t @ q[:, 0] + g, t @ q[:, 1] + s
        r0, r1 = a @ u0 - b, a @ u1
        bar = np.flatnonzero(self.contacts.where == BAR)
        dof = self.p2.dof_xyz[bar]
        if force is not None and len(bar):
            f0 = float((r0[dof] @ self.axis).sum())
            f1 = float((r1[dof] @ self.axis).sum())
            self.advance = (force - f0) / f1
        return u0 + self.advance * u1, r0 + self.advance * r1

    # -- the active-set rules -------------------------------------------------------------
    def update(self, u: np.ndarray, reaction: np.ndarray, u_start: np.ndarray, slip_scale_m: float) -> bool:
        """Apply the contact rules (module docstring); True when the set held and the springs settled.

        Friction is Coulomb's with an elastic stick (elastoplastic friction): a contact's
        tangential force is μ_f N min(1, |d|/ε) against d, its tangential displacement from
        its anchor, reached by reweighting a spring k = μ_f N / max(|d|, ε) each round
        (``slip_scale_m`` = ε); a contact that slides drags its anchor (:meth:`slide`)."""
        cs = self.contacts
        p = self.problem
        dof = self.p2.dof_xyz
        pts = self.surface
        x = self.rest[pts] + u[dof[pts]]
        where = cs.where[pts]
        on = where >= 0
        fr = self.frames(pts)
        normal = np.einsum("nk,nk->n", reaction[dof[pts]], fr[:, 0])
        scale = 1e-6 * float(np.abs(normal[on]).mean()) if on.any() else 0.0
        rel = x - self.tip
        along = rel @ self.axis
        across = np.linalg.norm(rel - along[:, None] * self.axis, axis=1)
        # a contact that pulls is released (it may not come back within the step: the
        # quadratic elements' vertex reactions can change sign as a patch forms); a point
        # that slid off the bar's face too
        release = on & ((normal < -scale) | ((where == BAR) & (across > p.radius_mm * MM)))
        # a free point that crossed the floor or the bar's face touches it
        gate = np.where(cs.left[pts], 1e-3 * self.size, self.gap_tol)
        below = ~on & (x[:, 1] < -gate)
        into_bar = ~on & ~below & self.pushing & (across <= p.radius_mm * MM) & (along < self.advance - gate)
        # what a settled round leaves behind the floor or the bar's face (contacts sit on them)
        pen = np.concatenate([[0.0], -x[~on & ~below, 1],
                              self.advance - along[~on & ~into_bar & (across <= p.radius_mm * MM)] if self.pushing else []])
        self.last_penetration_mm = float(pen.max()) / MM
        # the friction springs from this round's normal force and slip
        mu = np.where(where == BAR, p.bar_friction, p.floor_friction)
        slip = np.einsum("nk,nak->na", u[dof[pts]] - cs.anchor[pts], fr[:, 1:])
        spring = mu * np.maximum(normal, 0.0) / np.maximum(np.linalg.norm(slip, axis=1), slip_scale_m)
        old = cs.spring[pts]
        settled = np.abs(spring - old)[on] <= 1e-2 * np.maximum(spring, old)[on] + 1e-12
        changed = bool(release.any() or below.any() or into_bar.any() or not settled.all())
        cs.spring[pts[on]] = spring[on]
        cs.pressure[pts[on]] = np.maximum(normal[on], 0.0)
        k = pts[release]
        cs.where[k] = -1
        cs.left[k] = True
        cs.spring[k] = 0.0
        for mask, place in ((below, FLOOR), (into_bar, BAR)):
            k = pts[mask]
            cs.where[k] = place
            cs.spring[k] = 0.0
            cs.anchor[k] = u[dof[k]]
        return not changed

    def slide(self, u: np.ndarray, slip_scale_m: float) -> None:
        """End of a step: a contact farther than ε from its anchor has slid; the anchor follows to ε."""
        cs = self.contacts
        on = np.flatnonzero(cs.where >= 0)
        if len(on) == 0:
            return
        fr = self.frames(on)
        d = u[self.p2.dof_xyz[on]] - cs.anchor[on]
        tangential = d - np.einsum("nk,nk->n", d, fr[:, 0])[:, None] * fr[:, 0]
        size = np.linalg.norm(tangential, axis=1)
        far = size > slip_scale_m
        cs.anchor[on[far]] += tangential[far] * (1.0 - slip_scale_m / size[far])[:, None]

    def engage(self, u: np.ndarray, force: float) -> None:
        """A pushed bar with nothing under it moves to touch the nearest point (quasi-static)."""
        cs = self.contacts
        if force <= 0 or np.any(cs.where == BAR):
            return
        pts = self.surface
        x = self.rest[pts] + u[self.p2.dof_xyz[pts]]
        rel = x - self.tip
        along = rel @ self.axis
        across = np.linalg.norm(rel - along[:, None] * self.axis, axis=1)
        under = (across <= self.problem.radius_mm * MM) & (cs.where[pts] < 0)
        if not under.any():
            raise InputError("the bar's end face has no tissue under it", "bar")
        self.advance = float(along[under].min())
        first = pts[under & (along <= self.advance + 1e-6 * self.size)]
        cs.where[first] = BAR
        cs.spring[first] = 0.0
        cs.anchor[first] = u[self.p2.dof_xyz[first]]

    # -- steps ----------------------------------------------------------------------------
    def step(self, u: np.ndarray, v: np.ndarray, t_new: float, dt: float | None,
             rate: tuple[float, np.ndarray] | None = None) -> tuple[np.ndarray, bool]:
        """One implicit step from (u, v) over ``dt`` (None: static equilibrium); returns u and whether it settled.

        ``rate`` = (c0, r) says how the velocity at the step's end is formed, u̇₊ = (c0 u₊ − r)/Δt:
        backward Euler (1, u) by default, BDF2 from the caller's history."""
        c0, r = (1.0, u) if rate is None else rate
        force = float(self.problem.force_n(t_new)) if dt is not None else 0.0
        self.pushing = force > 0
        if not self.pushing:
            # no push: the bar does not hold the tissue; it follows it, touching (see ``follow``)
            self.contacts.where[self.contacts.where == BAR] = -1
        self.contacts.left[:] = False
        # a contact's friction is elastic up to this tangential displacement (Coulomb's law regularised)
        slip_scale = self.settings.stick_mm * MM
        a_base = self.stiffness
        if dt is None:
            a_base = a_base + self.regular * sp.identity(self.p2.dofs, format="csr")
            b_base = self.load.copy()
        else:
            a_base = a_base + self.mass / dt ** 2
            b_base = self.load + self.mass @ (u + dt * v) / dt ** 2
        mu = None
        if dt is not None and self.problem.beta1 > 0:
            mu = self.viscosity(self.strain_rate(v))
        ub = u.copy()
        settled = False
        assembled_for = c = None
        for _ in range(self.settings.max_rounds):
            self.stats["rounds"] += 1
            springs, pull = self.friction()
            a, b = a_base + springs, b_base + pull
            if mu is not None:
                if mu is not assembled_for:
                    c = self._assemble_viscous(mu) / dt
                    assembled_for = mu
                a = (a + c0 * c).tocsr()
                b = b + c @ r
            if self.pushing:
                self.engage(ub, force)
            unew, reaction = self.solve(a.tocsr(), b, force if self.pushing else None)
            if not self.pushing:
                self.follow(unew)
            quiet = self.update(unew, reaction, u, slip_scale)
            moved = float(np.abs(unew - ub).max())
            scale = float(np.abs(unew - u).max()) + 1e-9 * self.size
            ub = unew
            consistent = True
            if mu is not None:
                # μ to consistency: relaxed in log space by 1/(1 + β2), the exact step for the
                # power law's own fixed point (the plain iteration converges only by β2ⁿ)
                target = self.viscosity(self.strain_rate((c0 * unew - r) / dt))
                omega = 1.0 / (1.0 + max(self.problem.beta2, 0.0))
                new_mu = np.exp((1 - omega) * np.log(mu) + omega * np.log(target))
                consistent = float(np.abs(np.log(target / mu)).max()) < 1e-3
                if not consistent:
                    mu = new_mu
            if quiet and consistent and moved <= self.settings.rtol * scale:
                settled = True
                break
        if not settled:
            self.stats["unsettled_steps"] += 1
        self.stats["max_penetration_mm"] = max(self.stats["max_penetration_mm"], self.last_penetration_mm)
        self.slide(ub, slip_scale)
        return ub, settled

    def follow(self, u: np.ndarray) -> None:
        """An unloaded bar rests on the tissue: its face at the nearest point under it."""
        pts = self.surface
        x = self.rest[pts] + u[self.p2.dof_xyz[pts]]
        rel = x - self.tip
        along = rel @ self.axis
        across = np.linalg.norm(rel - along[:, None] * self.axis, axis=1)
        under = across <= self.problem.radius_mm * MM
        if not under.any():
            raise InputError("the bar's end face has no tissue under it", "bar")
        self.advance = float(along[under].min())

    def _viscous_operator(self) -> None:
        """What makes ∫ 2 μ ε(u):ε(v) fast for any μ at the quadrature points: each basis
        function's symmetric gradient, and where each element entry lands in one CSR pattern."""
        b = self.strain_basis
        grads = np.stack([b.basis[i][0].grad for i in range(b.Nbfun)])        # (30, 3, 3, e, q)
        sym = 0.5 * (grads + grads.transpose(0, 2, 1, 3, 4))
        # per quadrature point, (elements, 30, 9) contiguous: the element matrices are batched products
        self._sym = np.ascontiguousarray(sym.reshape(b.Nbfun, 9, *sym.shape[3:]).transpose(3, 2, 0, 1))
        self._dx = b.dx                                                        # (e, q) weights × |J|
        dofs = b.element_dofs                                                  # (30, e)
        rows = np.broadcast_to(dofs[:, None, :], (b.Nbfun, b.Nbfun, dofs.shape[1]))
        cols = np.broadcast_to(dofs[None, :, :], rows.shape)
        keys = (rows.transpose(2, 0, 1).astype(np.int64) * b.N + cols.transpose(2, 0, 1)).ravel()
        unique, self._slot = np.unique(keys, return_inverse=True)
        r, c = unique // b.N, unique % b.N
        self._pattern = (np.searchsorted(r, np.arange(b.N + 1)), c.astype(np.int32), len(unique))

    def _assemble_viscous(self, mu: np.ndarray) -> sp.csr_matrix:
        """``∫ 2 μ ε(u) : ε(v)`` (N·s/m) for μ (Pa·s) at the strain quadrature points, (elements, points)."""
        if not hasattr(self, "_slot"):
            self._viscous_operator()
        weight = 2.0 * mu * self._dx
        local = np.zeros((self._sym.shape[1], self._sym.shape[2], self._sym.shape[2]))
        for q in range(self._sym.shape[0]):
            sq = self._sym[q]
            local += np.matmul(sq * weight[:, q, None, None], sq.transpose(0, 2, 1))
        indptr, indices, nnz = self._pattern
        data = np.bincount(self._slot, weights=local.ravel(), minlength=nnz)
        n = self.p2.dofs
        return sp.csr_matrix((data, indices, indptr), shape=(n, n))



def creep_reference(problem: CreepingTissue, times_s: np.ndarray, settings: CreepFESettings | None = None,
                    progress: Callable[[float], None] | None = None) -> CreepFESolution:
    """Settle ``problem`` under gravity (frame 0), then push it; the creep at ``times_s`` (module docstring)."""
    started = time.perf_counter()
    settings = settings or CreepFESettings()
    times = np.asarray(times_s, float)
    if times.ndim != 1 or len(times) == 0 or times[0] != 0.0 or np.any(np.diff(times) <= 0):
        raise InputError("output times must start at 0 s and increase", "times_s")
    if problem.travel_mm is not None:
        raise InputError("the small-strain truth pushes its bar by a force; a bar in travel control needs "
                         "truth.solver = finite_strain", "bar.control")
    solver = _Solver(problem, settings)
    cs = solver.contacts
    # resting: the lowest surface points stand on the floor, stuck
    pts = solver.surface
    low = pts[solver.rest[pts, 1] <= solver.rest[pts, 1].min() + 1e-6 * solver.size]
    cs.where[low] = FLOOR
    n = solver.p2.dofs
    u, _ = solver.step(np.zeros(n), np.zeros(n), 0.0, None)
    advance0 = solver.advance
    t = 0.0
    breaks = sorted({b for b in problem.breakpoints_s if 0 < b < times[-1]} | {float(times[-1])})
    saved_t, saved_u, saved_adv, saved_f = [0.0], [u.copy()], [advance0], [0.0]
    # variable-step BDF2 (second order: the truth's time error must be far below the fitted
    # model's backward Euler); a kink of the schedule (t = 0, a breakpoint) restarts the
    # history with one backward-Euler step of ``first_step_s``
    history = [(0.0, u.copy())]
    dt = settings.first_step_s
    tol = settings.tolerance_mm * MM
    while t < times[-1] - 1e-12:
        nxt = next(b for b in breaks if b > t + 1e-12)
        dt = min(dt, settings.max_step_s)
        landing = t + dt >= nxt - 1e-9
        step_dt = nxt - t if landing else dt
        state, adv = cs.copy(), solver.advance
        u = history[-1][1]
        if len(history) == 1:
            rate, v = None, np.zeros(n)
        else:
            (t1, u1), (t2, u2) = history[-2], history[-1]
            w = step_dt / (t2 - t1)
            rate = ((1 + 2 * w) / (1 + w), (1 + w) * u2 - w * w / (1 + w) * u1)
            v = (u2 - u1) / (t2 - t1)
        unew, _ = solver.step(u, v, t + step_dt, step_dt, rate)
        err = 0.0
        if len(history) >= 3:
            # Milne's device: the quadratic extrapolation of the last three states is the predictor;
            # BDF2's local error is 2/11 of its difference from the corrector (constant-step constants)
            (ta, ua), (tb, ub), (tc, uc) = history[-3:]
            tn = t + step_dt
            la = (tn - tb) * (tn - tc) / ((ta - tb) * (ta - tc))
            lb = (tn - ta) * (tn - tc) / ((tb - ta) * (tb - tc))
            lc = (tn - ta) * (tn - tb) / ((tc - ta) * (tc - tb))
            err = 2.0 / 11.0 * float(np.abs(unew - (la * ua + lb * ub + lc * uc)).max())
        if err > tol and step_dt > 1e-6:
            solver.stats["rejected"] += 1
            solver.contacts, solver.advance = state, adv
            dt = step_dt * max(0.25, 0.9 * (tol / err) ** (1 / 3))
            continue
        solver.stats["steps"] += 1
        t += step_dt
        history = (history + [(t, unew.copy())])[-3:]
        saved_t.append(t)
        saved_u.append(unew.copy())
        saved_adv.append(solver.advance)
        saved_f.append(float(problem.force_n(t)))
        if landing and t < times[-1] - 1e-12:
            history, dt = [(t, unew.copy())], settings.first_step_s
        elif len(history) < 3:
            dt = step_dt
        else:
            grow = 2.0 if err == 0.0 else min(2.0, 0.9 * (tol / err) ** (1 / 3))
            dt = step_dt * max(grow, 0.5)
        if progress is not None:
            progress(min(t / times[-1], 1.0))
    st = np.asarray(saved_t)
    us = np.asarray(saved_u)
    k = np.clip(np.searchsorted(st, times, side="right") - 1, 0, len(st) - 2) if len(st) > 1 else np.zeros(len(times), int)
    if len(st) > 1:
        w = ((times - st[k]) / (st[k + 1] - st[k]))[:, None]
        frames = (1 - w) * us[k] + w * us[k + 1]
        adv = (1 - w[:, 0]) * np.asarray(saved_adv)[k] + w[:, 0] * np.asarray(saved_adv)[k + 1]
        force = np.interp(times, st, saved_f)
    else:
        frames, adv, force = us[[0]], np.asarray(saved_adv[:1]), np.zeros(1)
    stats = {**solver.stats, "dofs": n, "tetrahedra": int(solver.p2.mesh.t.shape[1]),
             "advance_at_rest_mm": advance0 / MM,
             "wall_s": time.perf_counter() - started}
    return CreepFESolution(times, frames, (adv - advance0) / MM, force, stats, solver.p2)


__all__ = ["CreepingTissue", "CreepFESettings", "CreepFESolution", "creep_reference"]
