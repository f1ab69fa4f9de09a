"""The reduced forward model: the fast path's creep projected on the modes of its own runs (SI inside).

The fast path (:mod:`hifumotion.creep.integrate`) solves, per backward-Euler step, a system of three
unknowns per voxel corner (≈ 17,000 at the paper's 4,399 particles) with contacts as
constraints, several rounds a step. The motion those steps produce lives in a space of
a few tens of shapes: the bar's indentation, the bulge beside it, the creep that follows.
This module keeps only those (proper orthogonal decomposition, POD) and integrates the
same equation of motion in them (Galerkin projection, Goury & Duriez, IEEE T-RO 2018;
SOFA's ModelOrderReduction):

* **Basis.** Snapshots are full runs' displacements since their settled state, each with
  the bar's advance s beside the node displacements: ``x = [u; s]``. The left singular
  vectors ``V = [V_u; v_s]`` that hold all but ``1 − energy`` of the snapshots' squared
  norm are the modes (:func:`pod_basis`). A mode is a combination of snapshots, so it keeps
  every linear constraint all of them keep: a floor node that stuck in every snapshot stays
  on the floor, the nodes under the bar's face move with its advance. The other candidates'
  non-penetration is a small contact solve a step (:meth:`ReducedCreep._solve`); their
  sliding meets Coulomb's friction (:mod:`.friction`).
* **Equation.** ``u = u₀ + V_u q``, ``s = s₀ + v_sᵀ q`` from the settled state (u₀, s₀),
  in equilibrium under gravity and F(0). Backward Euler on Eq. 12–16's forces, projected:

      (K_r + C_r(μ)/Δt + M_r/Δt²) q₊ = (F(t₊) − F(0)) v_s + M_r/Δt² (q + Δt q̇) + C_r(μ)/Δt q

  with ``K_r = 2G V_uᵀ K_dev V_u + κ V_uᵀ K_vol V_u`` (E and ν scale two matrices made
  once), ``C_r(μ) = Σ_e μ_e V_eᵀ C_e V_e`` (Eq. 16's μ per voxel from its shear rate, the
  full model's rate on ``V_u q̇``, read from q̇ directly (:func:`.hyper.shear_rates`): the
  viscosity's non-linearity is kept whole; optionally on ECSW's sampled voxels, :mod:`.hyper`),
  ``M_r = V_uᵀ M V_u``. A corotational mesh (``CreepSettings.kinematics``) turns K with each
  voxel: its reduced force and K_R,r are taken on ECSW's sampled voxels at each step's guess
  and again by the step's rounds while the solution turns on (:mod:`.corotated_force`).
  The force F(t) does the work
  ``F s``, so its generalised force is ``F v_s``. The contacts' normal reactions do no work
  on the modes (a pressed node moves only along its surface), so they leave the projected
  equation; their friction does, and stays (``Wᵀ f``, :mod:`.friction`).
* **Steps** as the full model's: the local error ``½ Δt |u̇₊ − u̇|`` held near
  ``tolerance`` spacings on a ladder of step sizes, landing on the force schedule's
  breakpoints, frames interpolated between steps.

One step costs a dense r × r solve and the voxels' rates: about 10⁴ times less than the
full step at r ≈ 20 (docs/decisions.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np

from hifumotion.reduced.hyper import SampledViscosity, ecsw, rate_modes, shear_rates
from hifumotion.creep.integrate import CreepMaterial, CreepResult
from hifumotion.reduced.nnls import load_compiled, nnls_from
from hifumotion.reduced.bar_rows import ReducedBarRows
from hifumotion.reduced.corotated_force import CandidateForces, CorotatedForce, ReducedCorotation, TurnedViscosity
from hifumotion.reduced.friction import FrictionState, ReducedFriction
from hifumotion.creep.settings import ReducedSettings
from hifumotion.errors import InputError

MM = 1e-3


@dataclass(frozen=True)
class ReducedBasis:
    """The modes of the motion from a settled state (SI).

    Attributes
    ----------
    node_modes_m
        ``(3n, r)`` node displacements (m) per unit of each reduced coordinate; orthonormal
        together with ``advance_modes_m``.
    advance_modes_m
        ``(r,)`` the bar's advance (m) per unit of each coordinate.
    settled_nodes_mm
        ``(n, 3)`` the nodes of the settled state the snapshots started from (mm).
    advance_at_rest_mm
        The bar's advance at rest from its scene tip (mm), as :class:`~hifumotion.creep.integrate.CreepResult`'s.
    singular_values
        Every singular value of the snapshot matrix (the energy the modes keep).
    max_motion_mm
        The largest node displacement in the snapshots (mm).
    training_rates
        ``(J, r)`` the snapshots' reduced velocities (1/s), frame to frame: what the
        viscosity's hyper-reduction (:mod:`.hyper`) is fitted on.
    snapshot_coordinates
        ``(r, S)`` every snapshot frame's reduced coordinates (m): where the runs went.
    """

    node_modes_m: np.ndarray
    advance_modes_m: np.ndarray
    settled_nodes_mm: np.ndarray
    advance_at_rest_mm: float
    singular_values: np.ndarray
    max_motion_mm: float
    training_rates: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    snapshot_coordinates: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def size(self) -> int:
        return self.node_modes_m.shape[1]


def pod_basis(runs: Sequence[CreepResult], energy: float = 1.0 - 1e-8, max_modes: int = 40) -> ReducedBasis:
    """The POD modes of full runs' motion (each since its own frame 0, the settled state).

    ``energy``: the fraction of the snapshots' squared norm the modes keep; ``max_modes``
    caps their count. The settled state is the first run's.
    """
    if not runs:
        raise InputError("the reduced model needs at least one full run for its snapshots", "snapshots")
    if not 0.0 < energy < 1.0:
        raise InputError(f"energy must be in (0, 1), got {energy}", "energy")
    columns = []
    for r in runs:
        u = (r.nodes_mm - r.nodes_mm[:1]).reshape(len(r.nodes_mm), -1) * MM
        s = (r.advance_mm - r.advance_mm[0])[:, None] * MM
        columns.append(np.hstack([u, s])[1:])
    x = np.vstack(columns).T           # (3n + 1, snapshots)
    left, sigma, _ = np.linalg.svd(x, full_matrices=False)
    if sigma[0] <= 0:
        raise InputError("the full runs did not move: no modes to reduce onto", "snapshots")
    kept = np.cumsum(sigma ** 2) / np.sum(sigma ** 2)
    r = int(min(np.searchsorted(kept, energy) + 1, max_modes, len(sigma)))
    # each run's reduced velocity frame to frame (its first frame, the settled state, is q = 0)
    rates = []
    for run, col in zip(runs, columns):
        q = np.vstack([np.zeros((1, r)), col @ left[:, :r]])
        rates.append(np.diff(q, axis=0) / np.diff(run.times_s)[:, None])
    return ReducedBasis(np.ascontiguousarray(left[:-1, :r]), left[-1, :r].copy(), runs[0].nodes_mm[0].copy(),
                        float(runs[0].stats.get("advance_at_rest_mm", 0.0)), sigma,
                        float(np.sqrt((x[:-1].reshape(-1, 3, x.shape[1]) ** 2).sum(axis=1)).max()) / MM,
                        np.vstack(rates), left[:, :r].T @ x)


def held_on_solids(basis: ReducedBasis, solver, tolerance_m: float) -> ReducedBasis:
    """``basis`` with the nodes that lie on a plane or the bar's face at rest and stayed on it in
    every snapshot (their gap within ``tolerance_m`` throughout) held on it exactly: their
    modes' normal part set to zero on a plane, to the bar's advance on its face; then the modes
    made orthonormal again (column operations keep what the rows were set to, as both are
    linear in the columns).

    In the full model such a node's normal is eliminated while it presses, so the snapshots
    keep it on the plane up to their last digits and the onsets of other contacts; the modes
    then carry a normal part of 10⁻⁴–10⁻³ there, and each such node's contact row, touching at
    rest, is a constraint the contact solve can press: as many of them as there are modes lock
    the model (slide_stop_s49: 7 rows pressed on 7 modes stopped a slide at 3.7 of 10 mm,
    docs/decisions.md). Held, they slide along the plane and cannot leave it — the full model's
    pressed contact — and their rows vanish. ``tolerance_m`` 0 (or a basis without its snapshot
    coordinates) changes nothing."""
    snapshots = basis.snapshot_coordinates
    if tolerance_m <= 0 or snapshots.size == 0:
        return basis
    settled = basis.settled_nodes_mm * MM
    n = len(settled)
    v = basis.node_modes_m.reshape(n, 3, -1).copy()
    held = 0

    def hold(near: np.ndarray, direction: np.ndarray, moves_with: np.ndarray) -> int:
        """Hold the nodes ``near`` whose gap (their motion along ``direction`` less ``moves_with``
        per unit q) stayed within the tolerance in every snapshot: that gap set to zero."""
        gap_modes = np.einsum("k,nkr->nr", direction, v[near]) - moves_with[None]
        still = np.abs(gap_modes @ snapshots).max(axis=1) < tolerance_m
        v[near[still]] -= direction[None, :, None] * gap_modes[still][:, None, :]
        return int(still.sum())

    for k, plane in enumerate(solver.contacts.planes):
        if plane.bonded:
            continue
        normal = solver.contacts.body_frames[k, 0]
        gap = (settled - np.asarray(plane.point_m)) @ normal
        held += hold(np.flatnonzero(np.abs(gap) <= tolerance_m), normal, np.zeros(v.shape[2]))
    punch = solver.contacts.punch
    if punch is not None:
        # the bar's face: a node on it at rest whose gap to it stayed within the tolerance moves
        # with the bar along its axis — the full model's face contact, whose node takes the
        # bar's advance along its normal
        a = solver.contacts.body_frames[solver.contacts.punch_index, 0]
        rel = settled - (np.asarray(punch.tip_m) + basis.advance_at_rest_mm * MM * a)
        along = rel @ a
        across = np.linalg.norm(rel - along[:, None] * a, axis=1)
        held += hold(np.flatnonzero((np.abs(along) <= tolerance_m) & (across <= punch.radius_m)), a,
                     basis.advance_modes_m)
    if held == 0:
        return basis
    old_full = np.vstack([basis.node_modes_m, basis.advance_modes_m[None]])
    q, _ = np.linalg.qr(np.vstack([v.reshape(3 * n, -1), basis.advance_modes_m[None]]))
    change = q.T @ old_full                    # old coordinates → new ones
    return replace(basis, node_modes_m=np.ascontiguousarray(q[:-1]), advance_modes_m=q[-1].copy(),
                   training_rates=basis.training_rates @ change.T, snapshot_coordinates=change @ snapshots)


class ReducedCreep:
    """The creep of a voxel mesh in a :class:`ReducedBasis` (module docstring).

    Made once per mesh and basis from the full solver's matrices (``solver``, a
    :class:`~hifumotion.creep.integrate.CreepSolver` of the same mesh); each :meth:`run` takes its own
    material and force, so a fit's many parameter sets share it.
    """

    def __init__(self, solver, basis: ReducedBasis, settings: ReducedSettings | None = None):
        if solver.settings.kinematics not in ("small_strain", "corotational"):
            raise InputError(f"the reduced model is small-strain or corotational: kinematics = "
                             f"{solver.settings.kinematics} needs the implicit integrator", "kinematics")
        self.settings = settings or ReducedSettings()
        basis = self.basis = held_on_solids(basis, solver, self.settings.kept_on_solid * solver.dx_m)
        self.mesh = solver.mesh
        self.matrices = solver.matrices
        self.dx_m = solver.dx_m
        v = basis.node_modes_m
        m = solver.matrices
        k_dev, k_vol = m.matrix(1.0, 0.0, 0.0), m.matrix(0.0, 1.0, 0.0)
        self.deviatoric = v.T @ (k_dev @ v)     # per unit 2G
        self.volumetric = v.T @ (k_vol @ v)     # per unit κ
        # the loads in total, not from the settled state: a contact that held the weight must
        # give that reaction back before it opens (an increment could lift it off for free)
        settled_m = basis.settled_nodes_mm.ravel() * MM - solver.rest_m.ravel()
        self.settled_deviatoric = v.T @ (k_dev @ settled_m)
        self.settled_volumetric = v.T @ (k_vol @ settled_m)
        self.weight = v.T @ solver.body_force.ravel() - solver.anchor_stiffness * (v.T @ settled_m)
        self.mass = v.T @ (np.repeat(solver.mass, 3)[:, None] * v)
        self.anchor = solver.anchor_stiffness * (v.T @ v)
        # corotational: the elastic force turns with its voxels, on ECSW's sample (.reduced_corotation)
        self.corotation = None
        if solver.settings.kinematics == "corotational":
            self.corotation = ReducedCorotation(m, solver.rest_m, v, settled_m, basis.snapshot_coordinates,
                                                self.settings.corotation_tolerance, self.settings.hyper_samples)
        # Σ_e μ_e V_eᵀ C_e V_e: one r × r block per voxel
        elements = m.elements
        dofs = (3 * elements[:, :, None] + np.arange(3)).reshape(len(elements), 24)
        ve = v[dofs]                                        # (voxels, 24, r)
        blocks = np.empty((len(elements), v.shape[1], v.shape[1]))
        reg, dis = m.regular, m.distorted
        blocks[reg] = np.matmul(ve[reg].transpose(0, 2, 1), np.matmul(m.cube.viscous, ve[reg]))
        if len(dis):
            blocks[dis] = np.matmul(ve[dis].transpose(0, 2, 1), np.matmul(m.visc, ve[dis]))
        # the voxels whose viscosity is summed, with their weights: ECSW's sample or all of them
        modes_all = rate_modes(m, v, np.arange(len(elements)))
        self.sampled = SampledViscosity(np.arange(len(elements)), np.ones(len(elements)), 0.0)
        if self.settings.hyper_reduction and len(basis.training_rates) and solver.material.beta1 > 0:
            pick = np.unique(np.linspace(0, len(basis.training_rates) - 1, self.settings.hyper_samples).astype(int))
            self.sampled = ecsw(blocks, modes_all, basis.training_rates[pick], solver.material,
                                self.settings.hyper_tolerance)
        # the blocks are symmetric: their upper triangles, weighted, in single precision (the sum
        # over the voxels streams them once a step; 10⁻⁷ of C_r is far below the step's error)
        self._upper = np.triu_indices(v.shape[1])
        self.viscous = np.ascontiguousarray(
            blocks[self.sampled.voxels][:, self._upper[0], self._upper[1]] * self.sampled.weights[:, None], np.float32)
        self._n_voxels = len(elements)
        # each particle moves by its voxel corners' mean displacement (VoxelMesh.particles)
        # (3 × voxels, r): a frame's particles are one matrix product away
        self.particle_modes_mm = np.ascontiguousarray(ve.reshape(len(elements), 8, 3, -1).mean(axis=1).reshape(
            3 * len(elements), -1) / MM)
        self.settled_particles_mm = self.mesh.particles(basis.settled_nodes_mm)
        self.rows, self.bound, self._bar = self._contact_rows(solver.contacts)
        self._pressed = np.zeros(0, np.int64)   # the rows the last contact solve pressed (its warm start)
        load_compiled()                          # the contact solver's machine code, now rather than in a step
        self._linearised = (np.eye(basis.size), None)   # the last solve's matrix and pressed rows (solve_response)
        self.friction = None
        if self.settings.friction:
            reach = self.settings.contact_reach * self.dx_m + basis.max_motion_mm * MM
            self.friction = ReducedFriction(solver, v, basis.advance_modes_m, basis.settled_nodes_mm,
                                            basis.advance_at_rest_mm, reach, solver.settings.stick_mm * MM,
                                            self.settings.friction_touch * self.dx_m)
        # the voxels whose rates a step needs: the sample's, and those around the friction's
        # candidates (their normal reactions' viscous part)
        rated = self.sampled.voxels
        if self.friction is not None:
            rated = np.union1d(rated, self.friction.voxels)
        self._rated = rated
        self._rate_modes = modes_all[rated]
        self._sample_in_rated = np.searchsorted(rated, self.sampled.voxels)
        # corotational: the viscosity's rates and blocks turn with their voxels (updated in place),
        # and the friction's normal reactions take the turned elastic force
        self._turned_viscosity = self._candidate_forces = None
        if self.corotation is not None:
            self._turned_viscosity = TurnedViscosity(m, v, settled_m, rated, self._sample_in_rated,
                                                     self.sampled.weights, self._upper, self._rate_modes, self.viscous)
            if self.friction is not None and self.friction.size:
                self._candidate_forces = CandidateForces(m, solver.rest_m, v, settled_m, self.friction.voxels,
                                                         self.friction.nodes, self.friction.normals)

    def __setstate__(self, state: dict) -> None:
        # a model sent from a worker (Dask) or read from a cache: its first step should not pay
        # for loading the contact solver either
        self.__dict__.update(state)
        load_compiled()

    def _contact_rows(self, contacts) -> tuple[np.ndarray, np.ndarray, ReducedBarRows | None]:
        """Non-penetration of the contact candidates: the planes' as fixed ``rows @ q ≥ bound``
        (m), the bar's as :class:`~.bar_rows.ReducedBarRows`, linearised at each step's start.

        A plane candidate's gap is ``g₀ + G q``, ``n·(x − p)``; rows whose G vanishes (a node
        every mode keeps on its plane) are left out. A node that starts inside a plane may not go
        deeper (bound −max(g₀, 0))."""
        b = self.basis
        settled = b.settled_nodes_mm * MM
        v = b.node_modes_m.reshape(len(settled), 3, -1)
        # a node as far from a solid as the snapshots' largest motion may reach it
        reach = self.settings.contact_reach * self.dx_m + b.max_motion_mm * MM
        surface = np.unique(self.mesh.surface_faces())
        rows, bound = [np.zeros((0, b.size))], [np.zeros(0)]
        for k, plane in enumerate(contacts.planes):
            normal = contacts.body_frames[k, 0]
            gap = (settled[surface] - np.asarray(plane.point_m)) @ normal
            near = surface[gap < reach]
            rows.append(np.einsum("k,nkr->nr", normal, v[near]))
            bound.append(-np.maximum(gap[gap < reach], 0.0))
        rows, bound = np.vstack(rows), np.concatenate(bound)
        active = np.abs(rows).max(axis=1) > 1e-9 * max(np.abs(rows).max(initial=0.0), 1e-300)
        bar = None
        if contacts.punch is not None:
            # the bar meets the nodes as far as they move and as far as it moves
            travel = (float(np.abs(b.advance_modes_m @ b.snapshot_coordinates).max())
                      if b.snapshot_coordinates.size else 0.0)
            bar = ReducedBarRows(contacts, settled, v, b.advance_modes_m, b.advance_at_rest_mm * MM, surface,
                                 reach + travel)
        return np.ascontiguousarray(rows[active]), bound[active], bar

    def _rows_at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The contact rows that hold at ``q`` (``rows @ q₊ ≥ bound``; every plane's, the bar's
        linearised there) and their indices among all candidates' rows."""
        if self._bar is None:
            return self.rows, self.bound, np.arange(len(self.rows))
        # a step's friction rounds all solve at its start: the bar's rows are made once a step
        cached = getattr(self, "_rows_cache", None)
        if cached is not None and np.array_equal(cached[0], q):
            return cached[1]
        rows, bound, holds = self._bar.rows_at(q)
        index = np.concatenate([np.arange(len(self.rows)), len(self.rows) + np.flatnonzero(holds)])
        out = (np.vstack([self.rows, rows[holds]]), np.concatenate([self.bound, bound[holds]]), index)
        self._rows_cache = (q.copy(), out)
        return out

    def _solve(self, a: np.ndarray, rhs: np.ndarray, stats: dict, at: np.ndarray) -> np.ndarray:
        """``argmin ½ qᵀ a q − rhsᵀ q`` with the gap of every candidate that holds at ``at`` ≥ 0.

        A least-distance problem in ``y = Lᵀ q`` (``a = L Lᵀ``), solved by Lawson & Hanson's
        NNLS on a working set of rows — those the last solve pressed and those the
        unconstrained solution violates — grown by the rows each solution still violates,
        until none is (the result is then the whole problem's)."""
        q = np.linalg.solve(a, rhs)
        tol = self.settings.contact_tolerance * self.dx_m
        rows, bound, index = self._rows_at(at)
        violated = rows @ q < bound - tol
        if len(rows) == 0 or not violated.any():
            self._pressed = np.zeros(0, np.int64)
            self._linearised = (a, None)
            return q
        stats["contact_solves"] += 1
        inverse = np.linalg.inv(np.linalg.cholesky(a))          # L⁻¹ (r × r)
        y0 = inverse @ rhs
        h_rows = rows @ inverse.T                               # G L⁻ᵀ
        h = bound - h_rows @ y0
        pressed = np.isin(index, self._pressed)
        work = violated | pressed
        for _ in range(len(rows)):
            # NNLS starts from the rows pressed last (the last step's, then this solve's last round)
            z, weights, converged = _least_distance(h_rows[work], h[work], np.flatnonzero(pressed[work]))
            stats["nnls_fallbacks"] = stats.get("nnls_fallbacks", 0) + int(not converged)
            pressed[:] = False
            pressed[np.flatnonzero(work)[weights > 0]] = True
            outside = h_rows @ z < h - tol * 1e-3
            if not (outside & ~work).any():
                break
            work |= outside
        self._pressed = index[pressed]
        self._linearised = (inverse, h_rows[pressed])
        stats["contact_rows_worked"] = max(stats.get("contact_rows_worked", 0), int(work.sum()))
        return inverse.T @ (y0 + z)

    def solve_response(self, change: np.ndarray) -> np.ndarray:
        """How the last contact solve's ``q`` moves per unit change of its right-hand side along
        ``change`` (``(r,)`` or ``(r, c)``): its matrix inverted on the subspace the rows it
        pressed leave free, ``L⁻ᵀ (I − Π) L⁻¹ change`` with Π the projector onto the pressed
        rows' span in ``y = Lᵀ q`` — the derivative of the solution while the same rows press.
        After :meth:`step`, the step's linearised response (its last friction round's matrix):
        the online filter's Jacobian without a second step (:mod:`hifumotion.prediction.assimilate`)."""
        a, pressed = self._linearised
        if pressed is None:
            return np.linalg.solve(a, change)
        y = a @ change                     # a is L⁻¹ here
        if len(pressed):
            _, sigma, vt = np.linalg.svd(pressed, full_matrices=False)
            span = vt[sigma > 1e-10 * sigma[0]]
            y = y - span.T @ (span @ y)
        return a.T @ y

    def _viscosity(self, material: CreepMaterial, qdot: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 16's μ per voxel (Pa·s) at the shear rates of the reduced velocity ``qdot`` (on the
        voxels a step reads: ECSW's and the friction's), and C_r (r × r) of it; a corotational
        model's turned with its voxels at ``q``."""
        if self._turned_viscosity is not None:
            self._turned_viscosity.update(q, self.settings.tolerance * self.dx_m)
        rated = material.viscosity(shear_rates(self._rate_modes, qdot))
        mu = np.zeros(self._n_voxels)
        mu[self._rated] = rated          # the voxels no one reads are left at 0
        r = len(qdot)
        c = np.empty((r, r))
        c[self._upper] = rated[self._sample_in_rated].astype(np.float32) @ self.viscous
        c.T[self._upper] = c[self._upper]
        return mu, c

    def loads(self, material: CreepMaterial, friction: float | None = None) -> "ReducedLoads":
        """The material's reduced stiffness and its loads at q = 0 (the weight, less u₀'s elastic
        force); ``friction``: Coulomb's μ_f of the solids for this run (None: the one the model was
        made at — its snapshot runs' should span the μ_f it is run at)."""
        lam, g = material.lame()
        kappa = lam + 2 * g / 3
        scale = 1.0
        if friction is not None and self.friction is not None:     # (settings.friction off: none at all)
            if not (np.isfinite(friction) and friction >= 0):
                raise InputError(f"expected Coulomb's friction μ_f ≥ 0, got {friction}", "friction")
            made = self.friction.made_coefficient
            if made > 0:
                scale = friction / made
            elif friction > 0:
                # no candidates: the solids it was made with were frictionless
                raise InputError(f"the reduced model was made without friction; it cannot run at μ_f = {friction}",
                                 "friction")
        if self.corotation is None:
            return ReducedLoads(material, 2 * g * self.deviatoric + kappa * self.volumetric + self.anchor,
                                self.weight - 2 * g * self.settled_deviatoric - kappa * self.settled_volumetric,
                                2 * g, kappa, scale)
        # corotational: linearised at q = 0 (each step takes it again where it goes, :meth:`_elastic`)
        at_rest = self.corotation.at(np.zeros(self.basis.size), 2 * g, kappa)
        return ReducedLoads(material, at_rest.matrix + self.anchor, self.weight - at_rest.force, 2 * g, kappa, scale)

    def _elastic(self, loads: "ReducedLoads", at: np.ndarray) -> tuple[np.ndarray, np.ndarray, CorotatedForce | None]:
        """The elastic force (with the anchor, less the weight) linearised at ``at``: ``matrix @ q −
        load``, and the corotational force it was taken from (None: small strain, where it is
        ``loads``' own, exact at every q)."""
        if self.corotation is None:
            return loads.stiffness, loads.load, None
        # each voxel's part of the matrix is kept while its rotation is within a whole step tolerance
        # of the one it was taken at (ten times the rounds' criterion): a stale part by δθ errs by δθ
        # times the step's predictor error, far below the tolerance
        turned = self.corotation.at(at, loads.two_g_pa, loads.kappa_pa, self.settings.tolerance * self.dx_m)
        return turned.matrix + self.anchor, self.weight - turned.force + turned.matrix @ at, turned

    def _turned_on(self, turned: CorotatedForce | None, q: np.ndarray) -> bool:
        """Whether a corotational solution ``q`` turned from where its force was taken by more than
        a tenth of the step tolerance (the full model's criterion)."""
        return turned is not None and self.corotation.moved(turned, q, 0.1 * self.settings.tolerance * self.dx_m)

    def settle(self, loads: "ReducedLoads", force_n: float, stats: dict | None = None) -> "ReducedState":
        """Frame 0: static equilibrium under the weight and the bar's ``force_n`` (N) in this
        material (the snapshots' settled state u₀ was another material's)."""
        stats = step_counters(self) if stats is None else stats
        r = self.basis.size
        q = np.zeros(r)
        stiffness, load, turned = self._elastic(loads, q)
        for _ in range(1 + (4 * self.settings.rotation_rounds if turned is not None else 0)):
            q = self._solve(stiffness, load + force_n * self.basis.advance_modes_m, stats, np.zeros(r))
            if not self._turned_on(turned, q):
                break
            stiffness, load, turned = self._elastic(loads, q)
            stats["rotation_rounds"] += 1
        return self.lag_viscosity(ReducedState(0.0, q, np.zeros(r), np.zeros((r, r)), None), loads, force_n)

    def step(self, state: "ReducedState", loads: "ReducedLoads", dt: float, force_n: float,
             stats: dict | None = None, error: bool = True, advance_m: float | None = None
             ) -> tuple["ReducedState", float]:
        """One backward-Euler step of ``dt`` (s) from ``state`` with the bar's ``force_n`` (N) at its
        end; the new state and the step's local error (m, ½ Δt max |u̇₊ − u̇| over the nodes;
        NaN with ``error=False``, which saves a product over every node).

        ``advance_m`` (travel control): the bar's advance (m) from the snapshots' settled state
        at the step's end, given instead of its force (``force_n`` is then not read): held by a
        penalty, :func:`driven_bar`; the force it takes is ``stats["bar_force_n"]``."""
        stats = step_counters(self) if stats is None else stats
        q, qdot, visc = state.q, state.qdot, state.viscous
        dynamic = visc / dt + self.mass / dt ** 2
        inertia = self.mass @ (q + dt * qdot) / dt ** 2 + visc @ q / dt
        # the rounds: the friction linearised where the last round ended (first where the step's
        # rate would take it), at the normal reactions lagged a step, until its law holds at the
        # solution; a corotational force taken again there while the solution turns on
        guess = q + dt * qdot
        stiffness, load, turned = self._elastic(loads, guess)
        friction = state.friction
        rubbing = friction is not None and bool(np.any(friction.limit_n > 0))
        rounds = (max(self.settings.friction_rounds, 1) if rubbing else 1) + (
            self.settings.rotation_rounds if turned is not None else 0)
        for _ in range(rounds):
            a = stiffness + dynamic
            rhs = inertia + load
            spring = None
            if advance_m is None:
                rhs = rhs + force_n * self.basis.advance_modes_m
            else:
                spring, target = driven_bar(a, self.basis.advance_modes_m), float(advance_m)
                a = a + spring * np.outer(self.basis.advance_modes_m, self.basis.advance_modes_m)
                rhs = rhs + spring * target * self.basis.advance_modes_m
            held = True
            if rubbing:
                matrix, extra, law = self.friction.linearised(friction, guess)
                qnew = self._solve(a + matrix, rhs + extra, stats, q)
                stats["friction_rounds"] += 1
                held = self.friction.law_error(friction, law, qnew) <= self.settings.friction_rtol
            else:
                qnew = self._solve(a, rhs, stats, q)
            turning = self._turned_on(turned, qnew)
            if held and not turning:
                break
            guess = qnew
            if turning:
                stiffness, load, turned = self._elastic(loads, qnew)
                stats["rotation_rounds"] += 1
        qdot_new = (qnew - q) / dt
        err = 0.5 * dt * float(np.abs(self.basis.node_modes_m @ (qdot_new - qdot)).max()) if error else np.nan
        if spring is not None:
            stats["bar_force_n"] = spring * (target - float(self.basis.advance_modes_m @ qnew))
        return ReducedState(state.t_s + dt, qnew, qdot_new, visc, friction), err

    def lag_viscosity(self, state: "ReducedState", loads: "ReducedLoads", bar_force_n: float | None = None
                      ) -> "ReducedState":
        """``state`` with what the next step takes from it (lagged, as the full model's): Eq. 16's
        μ from its own rates, and the friction's normal reactions and slid anchors. With the
        bar's push ``bar_force_n`` (N) and ``settings.friction_balance``, the floor's and the face's
        reactions carry the sample's balance in all (:meth:`~.friction.ReducedFriction.balanced`)."""
        mu, visc = (None, state.viscous) if loads.material.beta1 <= 0 else self._viscosity(loads.material, state.qdot, state.q)
        friction = state.friction
        if self.friction is not None:
            gaps = self.friction.gaps_m(state.q)
            elastic = (None if self._candidate_forces is None else self._candidate_forces.normal_n(
                state.q, loads.two_g_pa, loads.kappa_pa, gaps <= self.friction.touch_m))
            reactions = self.friction.normal_reactions_n(loads.two_g_pa, loads.kappa_pa, state.q, state.qdot, mu, elastic)
            if bar_force_n is not None and self.settings.friction_balance:
                reactions = self.friction.balanced(reactions, gaps, bar_force_n)
            friction = self.friction.state(state.q, reactions, state.friction, scale=loads.friction_scale, gaps_m=gaps)
        return ReducedState(state.t_s, state.q, state.qdot, visc, friction)

    def particles_mm(self, qs: np.ndarray) -> np.ndarray:
        """``(frames, N, 3)`` particle positions (mm) of the reduced coordinates ``qs`` ``(frames, r)``."""
        qs = np.atleast_2d(qs)
        return self.settled_particles_mm[None] + (qs @ self.particle_modes_mm.T).reshape(len(qs), -1, 3)

    def run(self, material: CreepMaterial, force_n: Callable[[float], float], breakpoints_s: Sequence[float],
            output_times_s: np.ndarray, progress: Callable[[float], None] | None = None,
            nodes: bool = True, travel_m: Callable[[float], float] | None = None,
            friction: float | None = None) -> CreepResult:
        """Push from the settled state: ``force_n(t)`` (N) on the bar; frames at ``output_times_s``.

        ``travel_m(t)`` (travel control, m): the bar driven that far along its axis beyond
        where it rests on this material's settled state, ``force_n`` then not read (the
        force it takes is a result). Returns the full model's :class:`~hifumotion.creep.integrate.CreepResult`
        (nodes, particles, the bar's advance and force at every frame); ``nodes=False`` leaves
        the nodes out (none of the particles' consumers needs them; they cost as much again).
        ``friction``: Coulomb's μ_f of the floor, walls and bar's face (None: the one the model was
        made at; :meth:`loads`).
        """
        started = time.perf_counter()
        times = np.asarray(output_times_s, float)
        if times.ndim != 1 or len(times) == 0 or np.any(np.diff(times) <= 0) or times[0] < 0:
            raise InputError("output times must be increasing and ≥ 0 s", "output_times_s")
        st = self.settings
        b = self.basis
        r = b.size
        loads = self.loads(material, friction)
        f0 = 0.0 if travel_m is not None else float(force_n(0.0))
        stats = step_counters(self)
        self._pressed = np.zeros(0, np.int64)   # a run does not depend on the one before
        state = self.settle(loads, f0, stats)
        rest = float(b.advance_modes_m @ state.q)   # a driven bar's travel counts from its place at rest
        interval = float(np.median(np.diff(times))) if len(times) > 1 else max(times[0], 1.0)
        base = st.first_step_s or interval / 4.0
        level = 0
        breaks = sorted(x for x in breakpoints_s if x > 0) + [times[-1]]
        saved_t, saved_q, saved_f = [0.0], [state.q.copy()], [f0]
        calm = 0
        limit = st.tolerance * self.dx_m
        while state.t_s < times[-1] - 1e-12:
            t = state.t_s
            dt = min(base * 2.0 ** level, st.max_step_s)
            nxt = next(x for x in breaks if x > t + 1e-12)
            landing = t + dt >= nxt - 1e-9 * dt
            if landing:
                dt = nxt - t
            if travel_m is None:
                force = float(force_n(t + dt))
                new, err = self.step(state, loads, dt, force, stats)
            else:
                new, err = self.step(state, loads, dt, 0.0, stats, advance_m=rest + float(travel_m(t + dt)))
                force = stats["bar_force_n"]
            if err > 2.0 * limit and dt > 1e-6 * base and not (t == 0.0 and level < -12):
                stats["rejected"] += 1
                level -= 1
                calm = 0
                continue
            stats["steps"] += 1
            state = self.lag_viscosity(new, loads, force)
            saved_t.append(state.t_s)
            saved_q.append(state.q.copy())
            saved_f.append(force)
            calm = calm + 1 if err < 0.25 * limit else 0
            if calm >= 2 and not landing:
                level += 1
                calm = 0
            if progress is not None:
                progress(min(state.t_s / times[-1], 1.0))
        st_t, st_q = np.array(saved_t), np.array(saved_q)
        qs = np.stack([np.interp(times, st_t, st_q[:, k]) for k in range(r)], axis=1)   # (frames, r)
        nodes_mm = (b.settled_nodes_mm[None] + (qs @ b.node_modes_m.T).reshape(len(times), -1, 3) / MM if nodes
                    else np.zeros((len(times), 0, 3)))
        advance_mm = (qs - qs[:1]) @ b.advance_modes_m / MM
        force = np.interp(times, st_t, np.array(saved_f))
        stats.update(seconds=time.perf_counter() - started, advance_at_rest_mm=b.advance_at_rest_mm)
        return CreepResult(times, nodes_mm, self.particles_mm(qs), advance_mm, force, stats)


#: A driven bar's penalty: this many times the step matrix's largest diagonal entry along its
#: advance, so that it misses its schedule by ~10⁻⁶ of what the tissue's own stiffness would let it.
DRIVEN_PENALTY = 1e6


def driven_bar(a: np.ndarray, advance_modes_m: np.ndarray) -> float:
    """The penalty stiffness (N/m) that holds the bar's advance ``advance_modes_m @ q`` at its
    schedule in a step of matrix ``a``: its force is the spring's, ``k (target − s)``. A penalty
    rather than a multiplier keeps the contact solve's problem a least-distance one."""
    along = float(advance_modes_m @ advance_modes_m)
    if along <= 0.0:
        raise InputError("the reduced model's modes never move the bar: its travel cannot be driven "
                         "(snapshots of a bar that touched the tissue are needed)", "bar.control")
    return DRIVEN_PENALTY * float(np.abs(np.diag(a)).max()) / along


@dataclass(frozen=True)
class ReducedLoads:
    """A material's reduced stiffness (N/m per unit q²) and its loads at q = 0 (N per unit q);
    its 2G and κ (Pa); the run's μ_f over the one the model was made at."""

    material: CreepMaterial
    stiffness: np.ndarray
    load: np.ndarray
    two_g_pa: float
    kappa_pa: float
    friction_scale: float = 1.0


@dataclass(frozen=True)
class ReducedState:
    """Where the reduced model is: time (s), coordinates q, their rate (1/s), the viscosity
    C_r (N·s/m per unit q²) the next step takes (Eq. 16 at the last step's rates) and the
    friction's anchors and limits (None: no friction, or not yet lagged)."""

    t_s: float
    q: np.ndarray
    qdot: np.ndarray
    viscous: np.ndarray
    friction: FrictionState | None = None


def step_counters(model: ReducedCreep) -> dict:
    """The counters a run or a loop of steps keeps (steps, rejected, contact solves)."""
    return {"steps": 0, "rejected": 0, "modes": model.basis.size, "contact_solves": 0, "nnls_fallbacks": 0,
            "contact_rows": len(model.rows) + (model._bar.size if model._bar is not None else 0), "friction_rounds": 0,
            "friction_candidates": model.friction.size if model.friction is not None else 0,
            "viscous_voxels": model.sampled.size, "viscous_fit_residual": model.sampled.residual,
            "rotation_rounds": 0, "elastic_voxels": model.corotation.size if model.corotation is not None else 0,
            "elastic_fit_residual": model.corotation.residual if model.corotation is not None else 0.0}


def _least_distance(g: np.ndarray, h: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """The shortest ``z`` with ``g z ≥ h``, the constraints' NNLS weights (> 0: pressed) and
    whether the warm-started NNLS converged (else SciPy's solved it cold), by Lawson & Hanson's
    reduction to non-negative least squares (Solving Least Squares Problems, 1974, ch. 23),
    started from the constraints ``start`` (indices) guessed pressed."""
    e = np.vstack([g.T, h[None]])
    f = np.zeros(len(e))
    f[-1] = 1.0
    weights, converged = nnls_from(e, f, np.asarray(start, np.int64), 3 * max(e.shape[1], 1))
    if not converged:
        from scipy.optimize import nnls

        weights, _ = nnls(e, f, maxiter=50 * max(e.shape[1], 1))
    residual = e @ weights - f
    if abs(residual[-1]) < 1e-12:
        raise InputError("the reduced model's contacts cannot all be kept", "reduced model")
    return -residual[:-1] / residual[-1], weights, converged


__all__ = ["ReducedBasis", "ReducedSettings", "ReducedCreep", "ReducedLoads", "ReducedState", "pod_basis", "step_counters"]
