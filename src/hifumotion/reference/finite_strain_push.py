"""The twin's physics at finite strain: the tissue pushed by the bar, on FElupe (issue 41, part 1).

The problem is :class:`~.creep_fe.CreepingTissue`'s — the same tissue surface, law, pool, bar
and force schedule — and so is the answer (:class:`~.creep_fe.CreepFESolution`: the P2 nodes'
displacement at the requested times), so either truth serves the twin. What differs is the
mechanics, which shares neither the small-strain truth's nor the fitted model's
approximations:

* **Kinematics**: finite strain, total Lagrangian (FElupe), on the same ten-node tetrahedra
  of a TetGen quality mesh (:mod:`._p2`).
* **Law** (:mod:`.finite_strain`): a nearly incompressible neo-Hookean solid on a three-field
  form, and Eq. 16's rate-dependent viscosity as a Kelvin–Voigt stress from an incremental
  potential — checked against closed-form solutions at 30 % strain (tests/test_finite_strain.py).
* **Time**: backward Euler, steps of at most ``step_s`` that land on every output time and
  every kink of the schedule; a step that does not converge is halved. The push creeps over
  seconds, so the tissue's inertia (consistent mass, as the small-strain truth's) weighs
  ~10⁻⁸ of the forces; it is kept because it is what holds the rigid motion of a sample its
  contacts barely hold (the frictionless floor of a sliding push).
* **Contacts** (FElupe's penalty contact with rigid planes, Coulomb friction with an
  elastic slip): the floor y = 0 under every surface node, and the bar's flat end under the
  surface nodes whose rest position lies within its radius of its axis. The bar is a rigid
  body that translates along its axis; the force schedule F(t) pushes it. Its axial stiffness
  is the tissue's alone: to keep Newton's steps defined while it is out of contact, its
  matrix (not its residual) holds a stiffness of the order of the tissue's under a punch,
  so the converged balance is exact. In travel control (``CreepingTissue.travel_mm``) the
  bar is driven instead: from where it rests on the settled tissue its point is prescribed
  ``travel(t)`` along the axis, and its force is the face contact's reaction.
* **Water**: the buoyant weight ``(ρ − ρ_w) g`` below the water line and ``ρ g`` above it,
  per quadrature point at its rest height (as the small-strain truth).

Units: mm, s, N at the interface and inside FElupe (stresses in MPa).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from hifumotion.errors import InputError
from hifumotion.reference._p2 import MM, p2_mesh, spsolve
from hifumotion.reference.creep_fe import CreepFESolution, CreepingTissue
from hifumotion.reference.finite_strain import PA_TO_MPA, TissueLaw

@dataclass
class FiniteStrainSettings:
    """Numerical settings: the largest step (s), the contacts' penalty (a multiple of the
    tissue's mean stiffness at the contact points; the bar's face, which takes the whole push on
    a few nodes where the floor spreads the weight over many, ten times the floor's: at the
    floor's × 100 the small twin's face penetrated 0.023 mm, above 1 % of its spacing, and
    × 1,000 moves the field by 3 %, docs/decisions.md), how far beyond its radius a driven bar's
    face takes contact candidates (this many times its largest travel: the sample it slides moves
    under it — a face tilted 30° outruns its own travel by 1.5 times), the elastic slip of a sticking contact
    (mm), and Newton's tolerance: the largest residual force (N) of a solve as a fraction of
    its push plus the tissue's weight. At 10⁻² the push's field is within 0.2 % of FElupe's
    own measure at 10⁻⁴ (which bounded the residual by ~3 % of the push) and the settle under
    gravity converges (it did not: its shape changed by half with the mesh); below ~10⁻³ the
    contacts' penalty switching holds Newton's residual near 4 × 10⁻⁴ of the push and the
    steps crawl (docs/decisions.md, issue 41)."""

    step_s: float = 0.05
    contact_multiplier: float = 100.0
    face_contact_multiplier: float = 1000.0
    face_reach_factor: float = 2.0
    elastic_slip_mm: float | None = 0.005
    newton_tol: float = 1e-2
    max_halvings: int = 8

    def __post_init__(self):
        for name in ("step_s", "contact_multiplier", "face_contact_multiplier", "face_reach_factor", "elastic_slip_mm",
                     "newton_tol"):
            value = getattr(self, name)
            if value is None and name == "elastic_slip_mm":
                continue
            if not (np.isfinite(value) and value > 0):
                raise InputError(f"must be a finite number > 0, got {value}", name)


class _Item:
    """The FElupe item protocol for a force and stiffness assembled here (``vector`` is the
    residual's contribution: internal minus external force, N; ``matrix`` its derivative)."""

    def __init__(self, field):
        from felupe.mechanics._helpers import Assemble, Results

        self.field = field
        self.results = Results()
        self.assemble = Assemble(vector=self._vector, matrix=self._matrix)

    def _size(self) -> int:
        return int(np.sum(self.field.fieldsizes))

    def _vector(self, field=None, parallel=False):
        import scipy.sparse as sp

        if field is not None:
            self.field = field
        self.results.force = sp.csr_matrix(self.residual().reshape(-1, 1))
        return self.results.force

    def _matrix(self, field=None, parallel=False):
        if field is not None:
            self.field = field
        self.results.stiffness = self.stiffness()
        return self.results.stiffness


class _Weight(_Item):
    """Gravity and the water's buoyancy: constant nodal forces (N) on the tissue."""

    def __init__(self, field, nodal_force_n: np.ndarray):
        super().__init__(field)
        self.force = nodal_force_n

    def residual(self):
        out = np.zeros(self._size())
        out[: self.force.size] = -self.force.ravel()
        return out

    def stiffness(self):
        import scipy.sparse as sp

        return sp.csr_matrix((self._size(), self._size()))


class _Bar(_Item):
    """The bar: a rigid body at point ``point`` that translates along the unit ``axis`` only,
    pushed along it by ``force_n``. Off the axis its motion is held by a stiff penalty; along
    it, while its face ``contact`` touches nothing, the matrix holds ``axial_n_per_mm`` that the
    residual does not (module docstring) — once it touches, the contact's own stiffness is
    exact and Newton converges quadratically."""

    def __init__(self, field, point: int, axis: np.ndarray, axial_n_per_mm: float, contact):
        super().__init__(field)
        self.contact = contact
        self.dofs = 3 * point + np.arange(3)
        self.axis = np.asarray(axis, float) / np.linalg.norm(axis)
        self.off_axis = np.eye(3) - np.outer(self.axis, self.axis)
        self.k_axial = float(axial_n_per_mm)
        self.k_off = 1e4 * float(axial_n_per_mm)
        self.force_n = 0.0

    def update(self, force_n):
        self.force_n = float(np.asarray(force_n).ravel()[0])

    def displacement_mm(self) -> np.ndarray:
        return self.field[0].values.ravel()[self.dofs]

    def residual(self):
        out = np.zeros(self._size())
        out[self.dofs] = self.k_off * (self.off_axis @ self.displacement_mm()) - self.force_n * self.axis
        return out

    def stiffness(self):
        import scipy.sparse as sp

        active = getattr(self.contact.results, "active", None)
        axial = 0.0 if active is not None and bool(np.any(active)) else self.k_axial
        block = self.k_off * self.off_axis + axial * np.outer(self.axis, self.axis)
        rows, cols = np.meshgrid(self.dofs, self.dofs, indexing="ij")
        n = self._size()
        return sp.csr_matrix((block.ravel(), (rows.ravel(), cols.ravel())), shape=(n, n))


class _Inertia(_Item):
    """The tissue's inertia in a backward-Euler step: ``M (u − uₙ − Δt vₙ) / Δt²`` (N) with the
    consistent mass ``M`` (kg, over every dof of the field; u in mm, so the force carries
    10⁻³). Its forces are ~10⁻⁸ of the push's, but it is what holds a body's rigid motion when
    its contacts barely do — a buoyant sample under a bar that touches it at a node (as the
    small-strain truth's consistent mass)."""

    def __init__(self, field, mass_kg):
        import scipy.sparse as sp

        super().__init__(field)
        self.solution = field[0]            # the unknowns' own field (Newton evaluates trial copies)
        self.mass = sp.csr_matrix(mass_kg)
        self.dt = 1.0
        self.rest()

    def rest(self) -> None:
        """Start from rest where the tissue is now (after the settle)."""
        self.previous = self.solution.values.ravel().copy()
        self.velocity = np.zeros_like(self.previous)

    def start(self, dt_s: float) -> None:
        """A step of ``dt_s`` from the last accepted state."""
        self.dt = float(dt_s)

    def accept(self) -> None:
        """The step converged: its end is the next step's start."""
        now = self.solution.values.ravel().copy()
        self.velocity = (now - self.previous) / self.dt
        self.previous = now

    def residual(self):
        u = self.field[0].values.ravel()
        return self.mass @ (u - self.previous - self.dt * self.velocity) * (1e-3 / self.dt ** 2)

    def stiffness(self):
        return self.mass * (1e-3 / self.dt ** 2)


def _absolute_residual(dx, x, f, xtol, ftol, dof1=None, dof0=None, items=None):
    """FElupe's Newton check with the free dofs' residual in N (not over the reactions)."""
    free = f[dof1] if dof1 is not None else f
    fnorm = float(np.linalg.norm(free))
    xnorm = float(np.linalg.norm(dx))
    return xnorm, fnorm, bool(fnorm < ftol and xnorm < xtol)


def _weight_forces(region, points_mm: np.ndarray, problem: CreepingTissue) -> np.ndarray:
    """``(points, 3)`` nodal forces (N) of gravity less the buoyancy below the water line,
    integrated per quadrature point at its rest height."""
    cells = region.mesh.cells
    h = region.h                                                       # (nodes/cell, q, cells)
    xq = np.einsum("aqc,cai->qci", h, points_mm[cells])                # quadrature points (mm)
    density = np.full(xq.shape[:2], problem.density_kg_m3)
    if problem.water_line_mm is not None:
        density = density - np.where(xq[..., 1] < problem.water_line_mm, problem.water_density_kg_m3, 0.0)
    load = density * problem.gravity_m_s2 * 1e-9 * region.dV           # N per quadrature point (down)
    nodal = np.zeros(len(points_mm))
    np.add.at(nodal, cells, np.einsum("aqc,qc->ca", h, load))
    out = np.zeros((len(points_mm), 3))
    out[:, 1] = -nodal
    return out


def finite_strain_reference(problem: CreepingTissue, times_s: np.ndarray, settings: FiniteStrainSettings | None = None,
                            progress: Callable[[float], None] | None = None) -> CreepFESolution:
    """Settle ``problem`` under gravity, the bar touching (frame 0), then push it; the
    displacement at ``times_s`` (module docstring) as the small-strain truth returns it."""
    import felupe as fem

    started = time.perf_counter()
    s = settings or FiniteStrainSettings()
    times = np.asarray(times_s, float)
    if times.ndim != 1 or len(times) == 0 or times[0] != 0.0 or np.any(np.diff(times) <= 0):
        raise InputError("output times must start at 0 s and increase", "times_s")
    law = TissueLaw(problem.youngs_modulus_pa, problem.poisson_ratio, problem.beta1, problem.beta2,
                    problem.rate_floor_per_s)
    p2 = p2_mesh(problem.vertices_mm, problem.faces, problem.max_volume_mm3)
    points = p2.points_m / MM
    n_tissue = len(points)
    axis = np.asarray(problem.axis, float) / np.linalg.norm(problem.axis)
    tip = np.asarray(problem.tip_mm, float)
    size = float(np.ptp(points, axis=0).max())
    surface = np.flatnonzero(p2.on_surface)
    rel = points[surface] - tip
    lateral = np.linalg.norm(rel - np.outer(rel @ axis, axis), axis=1)
    footprint = surface[lateral <= problem.radius_mm]
    if len(footprint) == 0:
        raise InputError("no surface node lies under the bar's face", "tip_mm")
    # the face's contact candidates: the nodes under it at rest and, for a driven bar, those its
    # travel may slide under it (its contact plane is unbounded: facts.physicality checks that
    # it holds none beyond the face's rim)
    reach = 0.0
    if problem.travel_mm is not None:
        sampled = np.union1d(np.linspace(0.0, times[-1], 201), [b for b in problem.breakpoints_s if b <= times[-1]])
        reach = s.face_reach_factor * max(float(problem.travel_mm(t)) for t in sampled)
    near = surface[lateral <= problem.radius_mm + reach]
    # the face comes down along its axis to rest on the first node under it (as the
    # small-strain truth's): a bar whose tip starts millimetres away would take Newton's
    # steps of F/k to cross the gap
    rest = float(((points[footprint] - tip) @ axis).min())
    # a candidate off the face's disc behind its plane at rest is not under the bar: left out
    under_bar = np.union1d(footprint, near[(points[near] - tip) @ axis >= rest])
    # the rigid bodies' reference points, a hair inside the tissue so their contacts start active
    touch = 1e-6 * size
    floor_point = [points[:, 0].mean(), points[:, 1].min() + touch, points[:, 2].mean()]
    mesh = fem.Mesh(np.vstack([points, tip + (rest + touch) * axis, floor_point]), p2.tetra10_cells(), "tetra10")
    bar_point, floor_index = n_tissue, n_tissue + 1
    region = fem.RegionQuadraticTetra(mesh)
    u = fem.Field(region, dim=3)
    field = fem.FieldContainer([u])
    elastic, viscous = law.bodies(field, s.step_s)
    floor = fem.ContactRigidPlane(field, surface, floor_index, normal=[0.0, 1.0, 0.0], friction=problem.floor_friction,
                                  multiplier=s.contact_multiplier, items=[elastic], elastic_slip=s.elastic_slip_mm)
    def face_contact(nodes):
        return fem.ContactRigidPlane(field, nodes, bar_point, normal=axis, friction=problem.bar_friction,
                                     multiplier=s.face_contact_multiplier, items=[elastic], elastic_slip=s.elastic_slip_mm)

    # the settle sees the nodes under the face at rest only (the plane is unbounded: the wider
    # candidates of a driven bar, pressed while the tissue sinks, kept a sample from settling);
    # the push sees every candidate
    face = face_contact(footprint)
    # the tissue's stiffness under a punch of the bar's radius, 2 E a / (1 − ν²) (N/mm)
    punch = 2.0 * problem.youngs_modulus_pa * PA_TO_MPA * problem.radius_mm / (1.0 - problem.poisson_ratio ** 2)
    bar = _Bar(field, bar_point, axis, punch, face)
    weight = _Weight(field, _weight_forces(region, mesh.points[:n_tissue], problem))
    inertia = _Inertia(field, elastic.assemble.mass(problem.density_kg_m3 * 1e-9))
    boundaries = {"floor": fem.Boundary(u, mask=np.arange(mesh.npoints) == floor_index)}
    stats = {"steps": 0, "halvings": 0}

    # Newton stops when the free residual (N) is below newton_tol × (this solve's push + the
    # tissue's weight). FElupe's own measure divides the residual by 10⁻³ + |the floor's
    # reaction| (≈ that sum itself), which let it stay at a few % of the push and, in the
    # settle, at a tenth of the weight (docs/decisions.md, issue 41, session 25)
    weight_n = float(np.abs(weight.force).sum())

    def solve(items, force_n: float) -> bool:
        """One Newton solve with the bar's push ``force_n`` (N; a driven bar: the force scale of
        its last reaction, for the tolerance)."""
        snapshot = u.values.copy()
        step = fem.Step(items, ramp={bar: np.array([0.0 if driven else force_n])}, boundaries=boundaries)
        job = fem.Job([step], plugins=[fem.LinesearchPlugin()])
        try:
            tol_n = s.newton_tol * max(abs(force_n) + weight_n, 1e-9)
            job.evaluate(tol=tol_n, verbose=0, solver=spsolve, check=_absolute_residual)
        except (fem.NewtonConvergenceError, ArithmeticError, np.linalg.LinAlgError):
            u.values[:] = snapshot
            return False
        return True

    # frame 0: settled under gravity, the bar touching with no force
    driven = False
    if not solve([elastic, weight, floor, face, bar], 0.0):
        raise InputError("the tissue does not settle on the floor under gravity", "vertices_mm")
    if viscous is not None:        # the viscosity's memory starts from the settled shape
        viscous.assemble.vector(field)
        viscous.results.update_statevars()
    if len(under_bar) > len(footprint):
        face = face_contact(under_bar)
        bar.contact = face
    items = [elastic] + ([viscous] if viscous is not None else []) + [weight, inertia, floor, face, bar]
    at_rest = bar.displacement_mm().copy()

    def reaction_n() -> float:
        """The force (N) the tissue puts on the bar's face along its axis, at the current state."""
        vector = face.assemble.vector(field)
        vector = vector.toarray() if hasattr(vector, "toarray") else np.asarray(vector)
        return float(vector.ravel()[bar.dofs] @ axis)

    if problem.travel_mm is not None:
        # travel control: the bar's point prescribed from where it rests (its own item, which
        # balances a force, leaves the solve)
        driven = True
        items = items[:-1]
        boundaries["bar"] = fem.Boundary(u, mask=np.arange(mesh.npoints) == bar_point, value=at_rest.copy())
    last_reaction = 0.0
    inertia.rest()
    floor_y = floor_point[1] - touch                     # the floor's plane (the sample's lowest point at rest)
    face_at_rest = tip + (rest + touch) * axis           # the face's point before the bar moves

    contact_gap = 1e-3 * size      # a face node this close to the plane (mm) counts as held by it

    def measure() -> dict:
        """This frame's physicality (docs/decisions.md, issue 41): the smallest volume ratio J
        and the largest principal strain |λ − 1| over the quadrature points; how far the
        tissue's nodes lie inside the floor and inside the bar — *any* node within the face's
        radius of the moved axis, not only those the face contact was given at rest (a sample
        that slides under the bar brings others); and how far beyond the face's rim the
        contact plane holds a node (the contact's plane is unbounded, the bar's face is a disc)."""
        grad = field.extract(grad=True, add_identity=True)[0]
        c = np.einsum("kiqc,kjqc->qcij", grad, grad)
        stretch = np.sqrt(np.clip(np.linalg.eigvalsh(c), 0.0, None))
        x = mesh.points[:n_tissue] + u.values[:n_tissue]
        face = face_at_rest + bar.displacement_mm()
        along = (x - face) @ axis
        lateral = np.linalg.norm((x - face) - np.outer(along, axis), axis=1)
        inside = (along < 0.0) & (lateral <= problem.radius_mm)
        held = along[under_bar] <= contact_gap
        return {"smallest_jacobian": float(np.linalg.det(np.moveaxis(grad, (0, 1), (-2, -1))).min()),
                "largest_strain": float(np.abs(stretch - 1.0).max()),
                "floor_penetration_mm": float(max(0.0, floor_y - x[:, 1].min())),
                "face_penetration_mm": float(max(0.0, -along[inside].min(initial=0.0))),
                "held_beyond_rim_mm": float(max(0.0, (lateral[under_bar][held] - problem.radius_mm).max(initial=0.0)))}

    frames = [measure()]
    saved = [u.values[:n_tissue].copy()]
    advance0 = float(bar.displacement_mm() @ axis)
    advance, force = [0.0], [0.0]
    kinks = sorted({float(b) for b in problem.breakpoints_s if 0 < b < times[-1]} | set(times[1:].tolist()))
    t = 0.0
    for target in kinks:
        while t < target - 1e-12:
            dt = min(s.step_s, target - t)
            for _ in range(s.max_halvings + 1):
                if viscous is not None:
                    viscous.umat.kwargs["dtime_s"] = dt
                inertia.start(dt)
                if driven:
                    boundaries["bar"].update(at_rest + float(problem.travel_mm(t + dt)) * axis)
                push = last_reaction if driven else float(problem.force_n(t + dt))
                if solve(items, push):
                    inertia.accept()
                    break
                dt *= 0.5
                stats["halvings"] += 1
            else:
                raise InputError(f"the push does not converge at t = {t:.4g} s even in steps of {dt:.3g} s",
                                 "travel_mm" if driven else "force_n")
            t += dt
            stats["steps"] += 1
            if driven:
                last_reaction = reaction_n()
        if np.any(np.isclose(times, target)):
            saved.append(u.values[:n_tissue].copy())
            frames.append(measure())
            advance.append(float(bar.displacement_mm() @ axis) - advance0)
            force.append(last_reaction if driven else float(problem.force_n(target)))
        if progress is not None:
            progress(min(t / times[-1], 1.0))
    displacement = np.zeros((len(saved), p2.dofs))
    for f, values in enumerate(saved):
        for c in range(3):
            displacement[f, p2.dof_xyz[:, c]] = values[:, c] * MM
    per_frame = {key: [f[key] for f in frames] for key in frames[0]}
    stats.update({"dofs": int(u.values.size), "tetrahedra": int(len(mesh.cells)), "wall_s": time.perf_counter() - started,
                  "bar_nodes": int(len(under_bar)),
                  "advance_at_rest_mm": rest + touch + advance0,
                  "smallest_jacobian": min(per_frame["smallest_jacobian"]),
                  "largest_strain": max(per_frame["largest_strain"]),
                  "floor_penetration_mm": max(per_frame["floor_penetration_mm"]),
                  "face_penetration_mm": max(per_frame["face_penetration_mm"]),
                  "held_beyond_rim_mm": max(per_frame["held_beyond_rim_mm"]),
                  "frames": per_frame})
    return CreepFESolution(times, displacement, np.asarray(advance), np.asarray(force), stats, p2)


__all__ = ["FiniteStrainSettings", "finite_strain_reference"]
