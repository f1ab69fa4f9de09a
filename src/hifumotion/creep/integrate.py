"""The tissue's creep under the bar, integrated implicitly (the fast path; SI inside).

The tissue's motion under a slow push is an overdamped creep: inertia is negligible
beside the elastic and viscous forces, so the equation of motion

    M ü + C(μ) u̇ + K u = f_body + f_contact                    (Eq. 12–16's forces)

is taken by **backward Euler** with the displacement at the end of the step unknown,

    (M/Δt² + C/Δt + K) u₊ = f_body + M/Δt² (u + Δt u̇) + C/Δt u + f_contact,

``K`` the small-strain elasticity and ``C`` the Kelvin–Voigt viscosity of
:mod:`.hexahedra` (μ per voxel from the previous step's shear rate, Eq. 16: one Picard
step, as the explicit path's implicit viscosity) — or, with ``CreepSettings.kinematics``, the
elastic force of a large deformation linearised, ``K_lin u + loads`` (:mod:`.corotation`,
:mod:`.neo_hooke`), re-linearised by the step's rounds while the solution moves; ``M`` the
lumped real mass (no mass scaling: it only keeps a frictionless body's rigid modes well posed). Contacts are
constraints (:mod:`.contact`), eliminated from the system: each step solves the
symmetric positive-definite reduced system once per round. A round also linearises the
friction (Coulomb's with an elastic stick, :mod:`.contact`) at the last round's motion —
its tangent where a contact slides — and the rounds end when the contact set holds and
the law holds to ``friction_rtol`` of each contact's μ_f λ_n.

Steps adapt to the motion: the local error of backward Euler, ``½ Δt |u̇₊ − u̇|``, is
held near ``tolerance`` × Δx by doubling or halving the step (a ladder of sizes, so the
factorisation is reused while the size and the contact set hold; in between, conjugate
gradients preconditioned by the last factorisation absorb the change of μ). Steps land
on the force schedule's breakpoints; output frames are interpolated linearly between
the steps around them.

The bar is pushed by its force schedule (its advance one more unknown, balanced by its
contacts' reactions) or, in travel control, driven: its advance is given, its contacts'
normal displacements follow it, and the force it takes is their reactions' sum.

Water: the fast path carries it as buoyancy — each submerged voxel weighs
``(ρ − ρ_w) g V`` — and no drag (the hydrostatic pressure on a submerged surface sums
to exactly that force; its uniform compression ρ_w g h / K is below 10⁻³ here).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import scipy.sparse as sp

from hifumotion.physical import STANDARD_GRAVITY_M_S2, TISSUE_DENSITY_KG_M3, WATER_DENSITY_KG_M3
from hifumotion.creep.contact import SLIP, STICK, ContactSet, FrictionLinearised, ContactPlane, Punch, friction_linearised
from hifumotion.creep.corotation import Corotation
from hifumotion.creep.neo_hooke import NeoHooke
from hifumotion.creep.hexahedra import MeshMatrices, _positions
from hifumotion.creep.linear import Factor, FactorError, preconditioned_cg, refined_solve
from hifumotion.creep.eliminate import eliminated_matrix_data
from hifumotion.creep.settings import CreepSettings
from hifumotion.creep.voxels import VoxelMesh
from hifumotion.errors import InputError
from hifumotion.rheology import MU_MAX_PA_S, RATE_FLOOR_PER_S, viscosity_pa_s

MM = 1e-3
#: how far (spacings) a node released within a step must cross a surface to touch again in it
LEFT_TOLERANCE = 2e-3
#: Settling steps (s): from a millisecond, where inertia dominates a 1 mm voxel's stiffness,
#: to static equilibrium (M/Δt² below 10⁻⁸ of K).
SETTLE_STEPS_S = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 1e3)


#: ``CreepSettings.kinematics`` → the elastic force of a large deformation, made from the mesh's
#: matrices, its rest nodes (m), G and κ (Pa); None for small strain (f = K u).
LARGE_DEFORMATION = {
    "small_strain": lambda matrices, rest_m, shear_pa, bulk_pa: None,
    "corotational": lambda matrices, rest_m, shear_pa, bulk_pa: Corotation(matrices, rest_m, 2 * shear_pa,
                                                                           bulk_pa),
    "neo_hooke": lambda matrices, rest_m, shear_pa, bulk_pa: NeoHooke(matrices, rest_m, shear_pa, bulk_pa),
}


@dataclass(frozen=True)
class CreepMaterial:
    """The tissue (SI): Table 3's E, ν, β1, β2 and the regularisations of Eq. 16's μ."""

    youngs_modulus_pa: float
    poisson_ratio: float
    beta1: float = 1.0
    beta2: float = 0.5
    density_kg_m3: float = TISSUE_DENSITY_KG_M3
    rate_floor_per_s: float = RATE_FLOOR_PER_S
    mu_max_pa_s: float = MU_MAX_PA_S

    def lame(self) -> tuple[float, float]:
        """(λ, G) in Pa."""
        e, nu = self.youngs_modulus_pa, self.poisson_ratio
        if not e > 0:
            raise InputError(f"Young's modulus must be > 0 Pa, got {e}", "youngs_modulus_pa")
        if not -1.0 < nu < 0.5:
            raise InputError(f"Poisson's ratio must be in (−1, 0.5), got {nu}", "poisson_ratio")
        return e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))

    def viscosity(self, rate_per_s: np.ndarray) -> np.ndarray:
        """Eq. 16's μ = β1 max(γ̇, floor)^β2 (Pa·s), capped at ``mu_max_pa_s``."""
        return viscosity_pa_s(rate_per_s, self.beta1, self.beta2, self.rate_floor_per_s, self.mu_max_pa_s)


@dataclass(frozen=True)
class Surroundings:
    """Gravity (m/s², a vector) and the water the tissue sits in (none when ``water_line_m`` is None)."""

    gravity_m_s2: tuple[float, float, float] = (0.0, -STANDARD_GRAVITY_M_S2, 0.0)
    water_density_kg_m3: float = WATER_DENSITY_KG_M3
    water_line_m: float | None = None
    up: int = 1  # the axis along which the water line is measured


@dataclass
class CreepResult:
    """The fast path's output (mm, s).

    ``nodes_mm`` and ``particles_mm`` are ``(frames, ·, 3)`` positions of the voxel
    corners and of the particles (voxel centres); ``advance_mm`` the bar's advance along
    its axis since t = 0 (frame 0 is the settled state); ``bar_force_n`` the force the
    tissue took at each frame; ``stats`` counts steps, factorisations, solves, the worst
    penetration of any surface (mm) and the wall time (s).
    """

    times_s: np.ndarray
    nodes_mm: np.ndarray
    particles_mm: np.ndarray
    advance_mm: np.ndarray
    bar_force_n: np.ndarray
    stats: dict = field(default_factory=dict)


class CreepSolver:
    """Backward-Euler creep of a voxel mesh with contact constraints (module docstring)."""

    def __init__(self, mesh: VoxelMesh, material: CreepMaterial, surroundings: Surroundings,
                 planes: list[ContactPlane], punch: Punch | None, settings: CreepSettings | None = None):
        self.mesh = mesh
        self.material = material
        self.settings = settings or CreepSettings()
        self.dx_m = mesh.spacing_mm * MM
        self.rest_m = mesh.nodes_mm * MM
        n = mesh.n_nodes
        lam, g = material.lame()
        try:
            self.matrices = MeshMatrices(self.rest_m, mesh.elements, self.dx_m)
        except ValueError as exc:
            raise InputError(str(exc), "tissue mesh") from None
        self.assembly = self.matrices.assembly
        self.k_data = self.matrices.matrix(2 * g, lam + 2 * g / 3, 0.0).data
        # large deformations: the elastic force linearised per step and round (.corotation: the
        # voxels' rotations taken out; .neo_hooke: finite strain); None: small strain, f = K u
        self.large = LARGE_DEFORMATION[self.settings.kinematics](self.matrices, self.rest_m, g, lam + 2 * g / 3)
        self._linearised = None   # the step's linearisation: its stiffness_data and loads
        rows = np.repeat(np.arange(self.assembly.size), np.diff(self.assembly.indptr))
        # a spring of 10⁻¹⁰ of the mean stiffness ties every node to its rest place: a body on
        # frictionless contacts keeps a well-posed system when Δt is long (M/Δt² → 0); it moves
        # nothing measurable (the bar's force balance holds to 10⁻⁹)
        self.anchor_stiffness = 1e-10 * float(np.abs(self.k_data[rows == self.assembly.indices]).mean())
        volume = self.dx_m ** 3
        mass_e = np.full(len(mesh.elements), material.density_kg_m3 * volume)
        self.mass = np.zeros(n)
        np.add.at(self.mass, mesh.elements.ravel(), np.repeat(mass_e / 8.0, 8))
        weight = np.full(len(mesh.elements), material.density_kg_m3 * volume)
        if surroundings.water_line_m is not None:
            wet = mesh.centres_mm[:, surroundings.up] * MM < surroundings.water_line_m
            weight = weight - wet * surroundings.water_density_kg_m3 * volume
        self.body_force = np.zeros((n, 3))
        grav = np.asarray(surroundings.gravity_m_s2, float)
        for c in range(3):
            np.add.at(self.body_force[:, c], mesh.elements.ravel(), np.repeat(weight * grav[c] / 8.0, 8))
        self.diag_index = np.flatnonzero(rows == self.assembly.indices)
        if punch is not None:
            # the rim rounded at the bar's own edge or at the mesh's resolution, whichever is the
            # rounder (contact.py: why the edge is rounded; docs/decisions.md, "The voxels meet the surface")
            own = punch.edge_radius_m or 0.0
            punch = replace(punch, edge_radius_m=min(max(own, self.settings.bar_edge_spacings * self.dx_m),
                                                     punch.radius_m))
        self.contacts = ContactSet(self.rest_m, planes, punch)
        self.punch = punch
        self._fixed_pattern()
        self.advance_m = 0.0
        # a driven bar's advance at rest on the settled tissue (m): its travel counts from there;
        # None while the tissue settles (the bar then rests on it, as an unloaded bar does)
        self._rest_advance: float | None = None
        self._factor: Factor | None = None
        self._reduction_key = None
        self.stats = {"steps": 0, "rejected": 0, "factorisations": 0, "solves": 0, "cg_iterations": 0,
                      "rounds": 0, "polish_rounds": 0, "friction_rounds": 0, "linearisation_rounds": 0,
                      "max_penetration_mm": 0.0}

    # -- the linear system ------------------------------------------------------------
    def _matrices(self, dt: float, mu: np.ndarray | None) -> tuple[sp.csr_matrix, sp.csr_matrix | None]:
        """``A = K + C/Δt + M/Δt²`` and ``C/Δt`` (None without viscosity), on one CSR pattern."""
        asm = self.assembly
        lin = self._linearised
        data = (self.k_data if lin is None else lin.stiffness_data).copy()
        c = None
        if mu is not None and self.material.beta1 > 0:
            turned = None if lin is None else self.large.viscous_data(mu / dt, lin)
            c = (self.matrices.matrix(0.0, 0.0, mu / dt) if turned is None else
                 sp.csr_matrix((turned, asm.indices, asm.indptr), shape=(asm.size, asm.size)))
            data += c.data
        data[self.diag_index] += np.repeat(self.mass, 3) / dt ** 2 + self.anchor_stiffness
        return sp.csr_matrix((data, asm.indices, asm.indptr), shape=(asm.size, asm.size)), c

    def _step_system(self, u: np.ndarray, v: np.ndarray, dt: float, mu: np.ndarray | None
                     ) -> tuple[sp.csr_matrix, np.ndarray]:
        """The step's ``A`` and right-hand side (module docstring; with a large deformation's loads)."""
        a, c = self._matrices(dt, mu)
        base = self.body_force.ravel() + np.repeat(self.mass, 3) / dt ** 2 * (u + dt * v).ravel()
        if self._linearised is not None:
            base -= self._linearised.loads.ravel()
        if c is not None:
            base += c @ u.ravel()
        return a, base

    def _linearisation_moved(self, u: np.ndarray) -> bool:
        """A large deformation: whether the solution ``u`` moved from where the rounds linearised the
        elastic force by more than a tenth of the step's tolerance (its nodes, or a voxel's corners
        by its rotation); if so it is linearised again there."""
        if self.large is None:
            return False
        again = self.large.moved(self._linearised, u, 0.1 * self.settings.tolerance * self.dx_m)
        if again is None:
            return False
        self._linearised = again
        return True

    def _reduction(self):
        """``u = T q + g`` for the current contact set (cached by its version).

        The unknowns are the same for every contact set, so the reduced system keeps one
        sparsity pattern (its ordering and symbolic factorisation are made once): node i's
        three ``q`` are its displacement along the axes (free) or along its contact's frame
        (normal, two tangents), and a last one is the bar's advance s when there is a bar.
        A constrained unknown (a contact's normal, a bonded contact's tangents) has a zero
        column in T — its value is in ``g``, or in the s column for the bar's contacts — and
        an identity row in the reduced system. Returns (T, g, s's column or −1, constrained)."""
        key = self.contacts.version
        if self._reduction_key == key:
            return self._t, self._g_with_advance(), self._s_col, self._constrained
        cs = self.contacts
        n = len(self.rest_m)
        rows, cols, vals = [], [], []
        g = np.zeros((n, 3))
        free = np.flatnonzero(cs.body < 0)
        # the same map per node for the blockwise reduction (:mod:`.reduce`): u_i = P_i q_i + n_i s
        columns = np.zeros((n, 3, 3))
        columns[free] = np.eye(3)
        bar_normal = np.zeros((n, 3))
        rows.append((3 * free[:, None] + np.arange(3)).ravel())
        cols.append(rows[-1])
        vals.append(np.ones(3 * len(free)))
        contact = np.flatnonzero(cs.body >= 0)
        s_col = 3 * n if self.punch is not None else -1
        constrained = [3 * contact]
        if len(contact):
            frames = cs.frames_of(contact)
            const, coef = cs.prescribed_normal(contact)
            g[contact] += const[:, None] * frames[:, 0]
            stick = cs.status[contact] == STICK   # bonded: held rigidly
            held = np.einsum("nk,nak->na", cs.anchor[contact], frames[:, 1:])
            g[contact[stick]] += np.einsum("na,nak->nk", held[stick], frames[stick, 1:])
            constrained += [3 * contact[stick] + 1, 3 * contact[stick] + 2]
            slip = np.flatnonzero(cs.status[contact] == SLIP)
            for a in (1, 2):
                rows.append((3 * contact[slip][:, None] + np.arange(3)).ravel())
                cols.append(np.repeat(3 * contact[slip] + a, 3))
                vals.append(frames[slip, a].ravel())
                columns[contact[slip], :, a] = frames[slip, a]
            # a bar's contact moves (a·n) s along its normal n as the bar advances s
            on_punch = np.flatnonzero(coef != 0)
            bar_normal[contact[on_punch]] = coef[on_punch, None] * frames[on_punch, 0]
            if len(on_punch):
                rows.append((3 * contact[on_punch][:, None] + np.arange(3)).ravel())
                cols.append(np.full(3 * len(on_punch), s_col))
                vals.append(bar_normal[contact[on_punch]].ravel())
        size = 3 * n + (1 if s_col >= 0 else 0)
        if s_col >= 0 and (self._driven() or not np.any(cs.body == cs.punch_index)):
            # a bar touching nothing, or a driven one: its advance is no unknown of the tissue's
            # (an identity row); a driven bar's nodes take its advance in g
            constrained.append(np.array([s_col]))
            s_col = -1
        t = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, size))
        self._t, self._g_const, self._s_col = t, g.ravel(), s_col
        self._columns, self._bar_normal = columns, bar_normal
        self._constrained = np.concatenate(constrained).astype(np.int64)
        self._reduction_key = key
        return self._t, self._g_with_advance(), self._s_col, self._constrained

    def _driven(self) -> bool:
        """Whether the bar's advance is given this step (travel control, once the tissue has settled)."""
        return self.punch is not None and self.punch.driven and self._rest_advance is not None

    def _g_with_advance(self) -> np.ndarray:
        """``g`` of :meth:`_reduction` (m, flat): a driven bar's nodes at its face, where its advance puts it."""
        if not self._driven():
            return self._g_const
        return self._g_const + self.advance_m * self._bar_normal.ravel()

    def _fixed_pattern(self) -> None:
        """The reduced system's one CSR pattern: the mesh's node-pair blocks, plus a full row and
        column for the bar's advance (its contacts may be any nodes); and where its diagonal is."""
        asm = self.assembly
        ones = sp.csr_matrix((np.ones(len(asm.indices)), asm.indices, asm.indptr), shape=(asm.size, asm.size))
        if self.punch is not None:
            edge = sp.csr_matrix(np.ones((1, asm.size)))
            ones = sp.bmat([[ones, edge.T], [edge, sp.csr_matrix(np.ones((1, 1)))]], format="csr")
        ones.sort_indices()
        # the blockwise reduction (:mod:`.reduce`) writes in this order: A's rows, each with the
        # bar's column last, then the bar's row
        shift = np.arange(asm.size + 1) if self.punch is not None else 0
        if not np.array_equal(ones.indptr[:asm.size + 1], asm.indptr + shift):
            raise RuntimeError("the reduced pattern is not the mesh's with the bar's row and column")
        self._pattern = (ones.indptr.astype(np.int64), ones.indices.astype(np.int64))
        rows = np.repeat(np.arange(ones.shape[0]), np.diff(ones.indptr))
        self._pattern_diag = np.flatnonzero(rows == ones.indices)
        # where each node's own 3 × 3 block is (the friction's stiffness goes there)
        node = 3 * np.arange(asm.size // 3)[:, None, None]
        block_rows = np.broadcast_to(node + np.arange(3)[:, None], (len(node), 3, 3))
        block_cols = np.broadcast_to(node + np.arange(3)[None, :], (len(node), 3, 3))
        self._node_block = _positions(self._pattern[0], self._pattern[1], block_rows.ravel().astype(np.int64),
                                      block_cols.ravel().astype(np.int64)).reshape(-1, 3, 3)

    def _solve(self, a: sp.csr_matrix, rhs: np.ndarray, force_n: float, guess: np.ndarray | None,
               friction: FrictionLinearised | None = None, rtol: float | None = None):
        """The step's displacement (m, flat) and the bar's advance for one round's contact set
        and friction (its force −(c + S (q_t − anchor)) on the contacts' tangential unknowns q_t),
        to a relative residual ``rtol`` (default ``cg_rtol``; the system is kept for :meth:`_polish`)."""
        rtol = self.settings.cg_rtol if rtol is None else rtol
        t, g, s_col, constrained = self._reduction()   # s_col −1: no bar, or one touching nothing
        rhs_q = t.T @ (rhs - a @ g)
        if s_col >= 0:
            rhs_q[s_col] += force_n
        if friction is not None and len(friction.nodes):
            tangents = 3 * friction.nodes[:, None] + np.array([1, 2])
            rhs_q[tangents] += np.einsum("nab,nb->na", friction.stiffness_n_m, friction.anchor_t) - friction.constant_n
        rhs_q[constrained] = 0.0
        self.stats["solves"] += 1
        # the guess in reduced unknowns: T's columns are orthonormal but the bar's advance's
        x0 = None if guess is None else t.T @ (guess - g)
        if s_col >= 0 and guess is not None:
            x0[s_col] = self.advance_m
        if x0 is not None:
            x0[constrained] = 0.0
        # the last factorisation preconditions any later matrix (the same unknowns, the same
        # pattern): a new μ or Δt changes values, a contact set a few nodes apart a few rows.
        # A fresh factorisation only when conjugate gradients need more than their budget.
        reduced = self._with_friction(self._reduced(a, t), friction)
        if self._factor is not None and x0 is not None:
            def apply(q):
                return reduced @ q
            q, its, ok = preconditioned_cg(apply, rhs_q, self._factor, x0, rtol, self.settings.cg_iterations)
            self.stats["cg_iterations"] += its
        if self._factor is None or x0 is None or not ok:
            q = self._factorise(reduced, rhs_q, rtol)
        self._system = (reduced, rhs_q, q, t, g, s_col, rtol)
        return t @ q + g, (q[s_col] if s_col >= 0 else None)

    def _polish(self) -> tuple[np.ndarray, float | None]:
        """The last round's system solved on to ``cg_rtol`` from its round's solution."""
        reduced, rhs_q, q, t, g, s_col, rtol = self._system
        if rtol > self.settings.cg_rtol:
            q, its, ok = preconditioned_cg(lambda x: reduced @ x, rhs_q, self._factor, q, self.settings.cg_rtol,
                                           self.settings.cg_iterations)
            self.stats["cg_iterations"] += its
            if not ok:
                q = self._factorise(reduced, rhs_q, self.settings.cg_rtol)
        return t @ q + g, (q[s_col] if s_col >= 0 else None)

    def _polished(self, a: sp.csr_matrix, base: np.ndarray, unloaded: bool):
        """The last round's system solved to full accuracy (:meth:`_polish`) with the bar placed:
        the displacement (m) flat and ``(n, 3)``, and the constraints' reactions (N, ``(n, 3)``)."""
        new, s = self._polish()
        self._place_bar(new, s, unloaded)
        return new, new.reshape(-1, 3), (a @ new - base).reshape(-1, 3)

    def _factorise(self, reduced: sp.csr_matrix, rhs_q: np.ndarray, rtol: float) -> np.ndarray:
        """A fresh factorisation of ``reduced`` (in the last one's place: the analysis is kept on
        the same pattern) and the solution of ``rhs_q`` to a relative residual ``rtol``."""
        precision = self.settings.precision
        for attempt in (precision, "double"):
            if self._factor is None:
                self._factor = Factor(reduced, self.settings.solver, attempt)
            else:
                self._factor.refactor(reduced, attempt)
            self.stats["factorisations"] += 1
            try:
                q, its = refined_solve(reduced, self._factor, rhs_q, rtol, self.settings.cg_iterations)
                self.stats["cg_iterations"] += its
                return q
            except FactorError:
                # a system a single-precision factor cannot precondition (a body held by
                # nothing but its anchor springs while it settles): a double one
                self.stats["double_factorisations"] = self.stats.get("double_factorisations", 0) + 1
        raise FactorError("the creep's linear system could not be solved")  # pragma: no cover

    def _reduced(self, a: sp.csr_matrix, t: sp.csr_matrix) -> sp.csr_matrix:
        """Tᵀ A T on the fixed pattern, identity on the constrained unknowns; kept while the
        step's matrix and the contact set are the same."""
        key = (id(a), self.contacts.version)
        if getattr(self, "_reduced_key", None) != key:
            size = t.shape[1]
            indptr, indices = self._pattern
            # Pᵢᵀ Aᵢⱼ Pⱼ block by block on A's own pattern (:mod:`.reduce`)
            # a driven bar's advance is given: its nodes do not couple to it
            coupled = np.zeros_like(self._bar_normal) if self._driven() else self._bar_normal
            data = eliminated_matrix_data(a.indptr, a.indices, a.data, self._columns, coupled,
                                       self.punch is not None)
            # a constrained unknown's row is the identity times its node's mean diagonal (q = 0
            # there): the scale it has when it is free, so that the factorisation of one contact
            # set preconditions the next
            diagonal = a.data[self.diag_index]
            node_scale = np.append(diagonal.reshape(-1, 3).mean(axis=1), diagonal.mean())
            data[self._pattern_diag[self._constrained]] = node_scale[np.minimum(self._constrained // 3,
                                                                                len(node_scale) - 1)]
            self._reduced_matrix = sp.csr_matrix((data, indices, indptr), shape=(size, size))
            self._reduced_key = key
            self._reduced_of = a  # holds ``a`` alive, so its id is not reused while cached
        return self._reduced_matrix

    def _with_friction(self, reduced: sp.csr_matrix, friction: FrictionLinearised | None) -> sp.csr_matrix:
        """``reduced`` plus the friction's stiffness S on each contact's two tangential unknowns
        (inside their node's block of the fixed pattern)."""
        if friction is None or len(friction.nodes) == 0:
            return reduced
        indptr, indices = self._pattern
        data = reduced.data.copy()
        # the (2, 2) tangential part of each node's block, row by row as the stiffness
        data[self._node_block[friction.nodes][:, 1:, 1:].ravel()] += friction.stiffness_n_m.ravel()
        return sp.csr_matrix((data, indices, indptr), shape=reduced.shape)

    def _friction(self, u: np.ndarray, round_: int) -> FrictionLinearised:
        """The frictional contacts' law linearised at ``u`` (m, (n, 3)), at their last normal reactions."""
        cs = self.contacts
        nodes = cs.frictional()
        anchor_t = cs.tangential(nodes, cs.anchor)
        return friction_linearised(nodes, anchor_t, cs.tangential(nodes, u) - anchor_t, cs.friction_limit(nodes),
                                   self.settings.stick_mm * MM, newton=round_ < self.settings.newton_rounds)

    def _friction_settled(self, friction: FrictionLinearised, u: np.ndarray) -> bool:
        """Whether the round's linearised friction is the law at its solution and new normal reactions."""
        cs = self.contacts
        if len(friction.nodes) == 0:
            return True
        if np.any(cs.body[friction.nodes] < 0):
            return False   # a contact left: the next round's set differs anyway
        limit = cs.friction_limit(friction.nodes)
        d = cs.tangential(friction.nodes, u) - friction.anchor_t
        error = friction.error_n(d, limit, self.settings.stick_mm * MM)
        return bool(np.all(error <= self.settings.friction_rtol * (limit + limit.mean()) + 1e-300))

    # -- one step ---------------------------------------------------------------------
    def _engage_punch(self, u: np.ndarray, force_n: float) -> None:
        """A pushed bar with nothing under it advances until it touches (quasi-static)."""
        cs = self.contacts
        if self.punch is None or force_n <= 0 or np.any(cs.body == cs.punch_index):
            return
        gap, which = cs.gaps(u, self.advance_m)
        under = np.flatnonzero(which == cs.punch_index)
        if len(under) == 0:
            raise InputError("the bar's end face has no tissue under it", "bar")
        reach = float(gap[under].min())
        self.advance_m += reach
        # every node the face reaches together (a flat top meets it all at once)
        first = under[gap[under] <= reach + self.settings.contact_tolerance * self.dx_m]
        cs.touch(first, np.full(len(first), cs.punch_index), u, self.advance_m)
        # their share of the push until their reactions are known: the friction it allows holds
        # them from the first round (without it a body touched at a few points swings out of
        # place, and the next rounds' friction, lagging the normal reactions, does not bring it back)
        cs.pressure[first] = force_n / len(first)

    def _place_bar(self, u: np.ndarray, advance_m: float | None, unloaded: bool) -> None:
        """The bar after a solve: at the solved advance (m) where it was an unknown, resting on
        the tissue (``u``, m, flat) where it pushes nothing."""
        if advance_m is not None:
            self.advance_m = float(advance_m)
        if unloaded:
            self._follow(u.reshape(-1, 3))

    def _follow(self, u: np.ndarray) -> None:
        """An unloaded bar's face onto the nearest tissue under it (its advance, m); kept if none is."""
        along, under = self.contacts.under_face(u, 0.0)
        if under.any():
            self.advance_m = float(along[under].min())

    def step(self, u: np.ndarray, v: np.ndarray, t_new: float, dt: float,
             mu: np.ndarray | None) -> tuple[np.ndarray, float]:
        """Displacement (m, (n, 3)) at ``t_new`` after a step ``dt`` from (u, v); the bar's force taken."""
        if self._driven():
            # travel control: the bar is where its schedule puts it, and its force is what its
            # contacts take (no force balance: its advance is no unknown)
            self.advance_m = self._rest_advance + float(self.punch.travel_m(t_new))
            force, unloaded = 0.0, False
        else:
            force = float(self.punch.force_n(t_new)) if self.punch is not None else 0.0
            unloaded = self.punch is not None and force <= 0.0
        if unloaded:
            # a bar with no push holds nothing: it rests on the tissue and follows it after each
            # solve (as the twin's truth, reference.creep_fe.follow); held with zero force it
            # would leave its advance to contacts whose reactions must sum to nothing (chatter)
            self.contacts.release(self.contacts.on_bar())
        if self.large is not None:
            # the elastic force linearised at the step's predictor; the rounds take it on to the
            # solution's (.corotation, .neo_hooke): K_lin u + loads
            self._linearised = self.large.linearised(u + dt * v)
        a, base = self._step_system(u, v, dt, mu)
        self._engage_punch(u, force)
        guess = (u + dt * v).ravel()
        cs = self.contacts
        cs.left[:] = False
        tol = self.settings.contact_tolerance * self.dx_m
        for round_ in range(self.settings.max_rounds):
            self.stats["rounds"] += 1
            friction = self._friction(guess.reshape(-1, 3), round_)
            new, s = self._solve(a, base, force, guess, friction, self.settings.round_rtol)
            self._place_bar(new, s, unloaded)
            # the constraints' reactions: their normal parts set the friction's μ_f λ_n
            reaction = (a @ new - base).reshape(-1, 3)
            unew = new.reshape(-1, 3)
            changed = cs.update(unew, reaction, self.advance_m, tol, LEFT_TOLERANCE * self.dx_m, self.settings.round_rtol)
            if self.punch is not None and force > 0 and not np.any(cs.body == cs.punch_index):
                self._engage_punch(unew, force)
                changed = True
            guess = new
            if not changed and self._linearisation_moved(unew):
                # the solution moved on from where the elastic force was linearised: again there
                a, base = self._step_system(u, v, dt, mu)
                self.stats["linearisation_rounds"] += 1
                continue
            if not changed and self._friction_settled(friction, unew):
                # the round's system solved to full accuracy: a soft mode (a body held by a few
                # contacts, as a round-bottomed sample on two floor nodes) can move far between
                # the round's looser solve and this one, and take nodes through a surface
                new, unew, reaction = self._polished(a, base, unloaded)
                if not cs.update(unew, reaction, self.advance_m, tol, LEFT_TOLERANCE * self.dx_m, self.settings.round_rtol):
                    break
                self.stats["polish_rounds"] += 1
                guess = new
            elif not changed:
                self.stats["friction_rounds"] += 1
        else:
            new, unew, reaction = self._polished(a, base, unloaded)
        cs.record_pressure(reaction)
        cs.slide(unew, self.settings.stick_mm * MM)
        taken = cs.bar_force() if self.punch is not None else 0.0
        if self.punch is not None:   # after the force: its reactions are on the planes just solved
            cs.refresh_bar(unew, self.advance_m)
        gap, which = cs.gaps(unew, self.advance_m)
        touching = cs.body >= 0
        worst = float(np.max(-gap[~touching], initial=0.0)) / MM
        self.stats["max_penetration_mm"] = max(self.stats["max_penetration_mm"], worst)
        return unew, taken

    # -- the run ----------------------------------------------------------------------
    def run(self, output_times_s: np.ndarray, progress: Callable[[float], None] | None = None) -> CreepResult:
        """Settle under gravity (the bar at F(0)), then push; positions at ``output_times_s`` (≥ 0)."""
        started = time.perf_counter()
        times = np.asarray(output_times_s, float)
        if times.ndim != 1 or len(times) == 0 or np.any(np.diff(times) <= 0) or times[0] < 0:
            raise InputError("output times must be increasing and ≥ 0 s", "output_times_s")
        n = len(self.rest_m)
        st = self.settings
        cs = self.contacts
        u = self._settle()
        v = np.zeros((n, 3))
        t = 0.0
        interval = float(np.median(np.diff(times))) if len(times) > 1 else max(times[0], 1.0)
        base = st.first_step_s or interval / 4.0
        level = 0
        breaks = sorted(b for b in (self.punch.breakpoints_s if self.punch else ()) if b > 0) + [times[-1]]
        saved_t, saved_u, saved_adv, saved_force = [0.0], [u.copy()], [self.advance_m], [0.0]
        mu = None
        rate = np.zeros(len(self.mesh.elements))
        calm = 0
        while t < times[-1] - 1e-12:
            dt = min(base * 2.0 ** level, st.max_step_s)
            nxt = next(b for b in breaks if b > t + 1e-12)
            landing = t + dt >= nxt - 1e-9 * dt
            if landing:
                dt = nxt - t
            mu = self.material.viscosity(rate)
            adv0 = self.advance_m
            version0 = cs.version
            state = (cs.body.copy(), cs.status.copy(), cs.anchor.copy(), cs.pressure.copy(), cs.fresh.copy(),
                     cs.node_frames.copy(), cs.node_offset.copy())
            unew, taken = self.step(u, v, t + dt, dt, mu)
            vnew = (unew - u) / dt
            err = 0.5 * dt * np.abs(vnew - v).max()
            if err > 2.0 * st.tolerance * self.dx_m and dt > 1e-6 * base and not (t == 0.0 and level < -12):
                # reject: restore the contact state and halve
                self.stats["rejected"] += 1
                changed = cs.version != version0
                cs.body, cs.status, cs.anchor, cs.pressure, cs.fresh, cs.node_frames, cs.node_offset = state
                if changed:  # the set the factorisation knew is gone
                    cs.version += 1
                self.advance_m = adv0
                level -= 1
                calm = 0
                continue
            self.stats["steps"] += 1
            t += dt
            u, v = unew, vnew
            rate = self.matrices.rates(v) if self.large is None else self.large.rates(v, u)
            saved_t.append(t)
            saved_u.append(u.copy())
            saved_adv.append(self.advance_m)
            saved_force.append(taken)
            calm = calm + 1 if err < 0.25 * st.tolerance * self.dx_m else 0
            if calm >= 2 and not landing:
                level += 1
                calm = 0
            if progress is not None:
                progress(min(t / times[-1], 1.0))
        if self._factor is not None:
            self._factor.release()
            self._factor = None
        result = self._sampled(times, np.array(saved_t), np.array(saved_u), saved_adv, saved_force)
        self.stats["seconds"] = time.perf_counter() - started
        result.stats = dict(self.stats)
        return result

    def _settle(self) -> np.ndarray:
        """The settled displacement (m): the tissue at rest on its supports, the bar resting on it."""
        n = len(self.rest_m)
        st, cs = self.settings, self.contacts
        self._rest_advance = None
        # resting: the nodes on a surface start touching it, anchored where they are
        gap, which = cs.gaps(np.zeros((n, 3)), 0.0)
        resting = np.flatnonzero((which >= 0) & (which < cs.punch_index) & (gap <= st.contact_tolerance * self.dx_m))
        cs.touch(resting, which[resting], np.zeros((n, 3)))
        # settled state: the tissue let down onto the floor by quiet steps of growing length
        # (each from rest: inertia keeps a body that touches at a point well posed until its
        # contact patch has formed), then static equilibrium under gravity, no viscosity
        u = np.zeros((n, 3))
        for dt_settle in SETTLE_STEPS_S:
            u, _ = self.step(u, np.zeros((n, 3)), 0.0, dt_settle, None)
        if self.punch is not None:
            # the bar starts resting on the tissue (a gap would be crossed in no time by a
            # quasi-static push, and its travel counted as motion)
            gap, which = cs.gaps(u, self.advance_m)
            under = which == cs.punch_index
            if under.any():
                self.advance_m += float(gap[under].min())
            if self.punch.driven:
                self._rest_advance = self.advance_m
                cs.version += 1   # the bar's nodes now take its advance, not an unknown of their own
        return u

    def _sampled(self, times: np.ndarray, st_t: np.ndarray, st_u: np.ndarray, saved_adv: list, saved_force: list
                 ) -> CreepResult:
        """The accepted steps (times ``st_t`` s, displacements ``st_u`` m) interpolated linearly to
        the output times, in mm."""
        n = len(self.rest_m)
        nodes = np.empty((len(times), n, 3))
        for k, tk in enumerate(times):
            j = int(np.clip(np.searchsorted(st_t, tk), 1, len(st_t) - 1))
            w = 0.0 if st_t[j] == st_t[j - 1] else (tk - st_t[j - 1]) / (st_t[j] - st_t[j - 1])
            w = min(max(w, 0.0), 1.0)
            nodes[k] = self.rest_m + (1 - w) * st_u[j - 1] + w * st_u[j]
        nodes_mm = nodes / MM
        advance = np.interp(times, st_t, np.array(saved_adv) - saved_adv[0]) / MM
        force = np.interp(times, st_t, np.array(saved_force))
        self.stats["advance_at_rest_mm"] = saved_adv[0] / MM
        parts = np.stack([self.mesh.particles(f) for f in nodes_mm])
        return CreepResult(times, nodes_mm, parts, advance, force)   # run() adds its stats


__all__ = ["CreepMaterial", "Surroundings", "CreepSettings", "CreepResult", "CreepSolver"]
