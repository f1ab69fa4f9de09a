"""The twin's physics at finite strain: the tissue pushed by the bar, on FElupe.

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
* **Contacts** (FElupe's penalty node-to-rigid-surface contact, Coulomb friction with an
  elastic slip): the floor y = 0 under every surface node, and the bar as a solid — a
  cylinder of its radius whose flat end's edge is rounded (``CreepingTissue.edge_radius_mm``:
  face, quarter-torus rim and side, :func:`bar_gap`) — against every surface node, so
  tissue that bulges beside the bar or slides past its rim meets its side, not the end's
  plane continued beyond the rim. The bar is a rigid
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

from hifumotion.numerics import TRUTH_STEP_S
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
    × 1,000 moves the field by 3 %, docs/decisions.md), the elastic slip of a sticking contact
    (mm), and Newton's tolerance: the largest residual force (N) of a solve as a fraction of
    its push plus the tissue's weight. At 10⁻² the push's field is within 0.2 % of FElupe's
    own measure at 10⁻⁴ (which bounded the residual by ~3 % of the push) and the settle under
    gravity converges (it did not: its shape changed by half with the mesh); below ~10⁻³ the
    contacts' penalty switching holds Newton's residual near 4 × 10⁻⁴ of the push and the
    steps crawl (docs/decisions.md, "A finite-strain truth on FElupe")."""

    step_s: float = TRUTH_STEP_S
    contact_multiplier: float = 100.0
    face_contact_multiplier: float = 1000.0
    elastic_slip_mm: float | None = 0.005
    newton_tol: float = 1e-2
    max_halvings: int = 8

    def __post_init__(self):
        for name in ("step_s", "contact_multiplier", "face_contact_multiplier", "elastic_slip_mm",
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


def _advance_to_touch(offsets_mm: np.ndarray, axis: np.ndarray, radius_mm: float, edge_radius_mm: float) -> np.ndarray:
    """For points at ``offsets_mm`` from the centre of the bar's end (:func:`bar_gap`), how
    far (mm) the bar advances along its unit ``axis`` before it touches each: the axial offset,
    plus how far the rounded rim lies behind the face at that point's lateral distance (∞ for
    points beside the bar, which its side never meets by advancing)."""
    along = offsets_mm @ axis
    d = np.linalg.norm(offsets_mm - np.outer(along, axis), axis=1)
    core = radius_mm - edge_radius_mm
    behind = edge_radius_mm - np.sqrt(np.clip(edge_radius_mm ** 2 - (d - core) ** 2, 0.0, None))
    return np.where(d <= core, along, np.where(d <= radius_mm, along + behind, np.inf))


def bar_gap(offsets_mm: np.ndarray, axis: np.ndarray, radius_mm: float, edge_radius_mm: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bar as a rigid solid: a cylinder of ``radius_mm`` about the unit ``axis`` (pointing
    from the bar into the tissue) whose end, centred at the origin of ``offsets_mm``, is flat to
    a = ``radius_mm − edge_radius_mm`` and rounded to the side by a quarter torus of
    ``edge_radius_mm``; it extends without end behind its end.

    Returns, for points at ``offsets_mm`` (n, 3) from the end's centre, the signed distance g
    (mm; < 0 inside the bar), its gradient n and the gradient's derivative H (the curvature,
    1/mm), region by region (d: the point's distance from the axis):

    * face (d ≤ a): g = x·axis, n = axis, H = 0;
    * rim (d > a, in front of the torus's centre circle): the distance to that circle less r; n
      from the circle's nearest point, H = (I − n nᵀ − (a/d) e_θ e_θᵀ)/dist, e_θ circumferential;
    * side: g = d − R, n = e_r, H = e_θ e_θᵀ/d (a cylinder's).

    g and n are continuous across the regions — the rounding is what makes n so: a sharp edge
    has none."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    core, edge = radius_mm - edge_radius_mm, float(edge_radius_mm)
    along = offsets_mm @ a
    radial = offsets_mm - along[:, None] * a
    d = np.maximum(np.linalg.norm(radial, axis=1), 1e-9 * radius_mm)
    e_r = radial / d[:, None]
    face = d <= core
    rim = ~face & (along > -edge)
    side = ~face & ~rim
    gap = np.empty(len(offsets_mm))
    normal = np.empty_like(offsets_mm, dtype=float)
    curvature = np.zeros((len(offsets_mm), 3, 3))
    gap[face], normal[face] = along[face], a
    q = (d[rim] - core)[:, None] * e_r[rim] + (along[rim] + edge)[:, None] * a
    dist = np.maximum(np.linalg.norm(q, axis=1), 1e-9 * radius_mm)
    n = q / dist[:, None]
    gap[rim], normal[rim] = dist - edge, n
    hoop = np.eye(3) - np.outer(a, a) - np.einsum("ai,aj->aij", e_r, e_r)          # e_θ e_θᵀ
    curvature[rim] = (np.eye(3) - np.einsum("ai,aj->aij", n, n)
                      - (core / d[rim])[:, None, None] * hoop[rim]) / dist[:, None, None]
    gap[side], normal[side] = d[side] - radius_mm, e_r[side]
    curvature[side] = hoop[side] / d[side][:, None, None]
    return gap, normal, curvature


def _bar_contact(field, points, centerpoint, axis, radius_mm: float, edge_radius_mm: float, **kwargs):
    """The bar of :func:`bar_gap` as FElupe's rigid surface for its node-to-surface contact
    (penalty, Coulomb friction) between ``points`` and the centre point of its end."""
    import felupe as fem

    if not 0.0 < edge_radius_mm <= radius_mm:
        raise InputError(f"must be > 0 and at most the bar's radius ({radius_mm:g} mm), got {edge_radius_mm:g}",
                         "edge_radius_mm")
    shape = (np.asarray(axis, float), float(radius_mm), float(edge_radius_mm))

    class BarSurface(fem.mechanics.ContactRigidBase):
        def _kinematics(self, dx):
            return bar_gap(dx, *shape)

    return BarSurface(field, points, centerpoint, **kwargs)


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
    # the bar comes down along its axis to rest on the first node it meets (as the
    # small-strain truth's): a bar whose tip starts millimetres away would take Newton's
    # steps of F/k to cross the gap
    touch_at = _advance_to_touch(points[surface] - tip, axis, problem.radius_mm, problem.edge_radius_mm)
    if not np.isfinite(touch_at).any():
        raise InputError("no surface node lies under the bar's face", "tip_mm")
    rest = float(touch_at.min())
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
    # the bar against every surface node: a solid, it holds only what touches its face, rim or side
    face = _bar_contact(field, surface, bar_point, axis, problem.radius_mm, problem.edge_radius_mm,
                        friction=problem.bar_friction, multiplier=s.face_contact_multiplier, items=[elastic],
                        elastic_slip=s.elastic_slip_mm)
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
    # settle, at a tenth of the weight (docs/decisions.md, "A finite-strain truth on FElupe")
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

    def measure() -> dict:
        """This frame's physicality (docs/decisions.md, "A finite-strain truth on FElupe"): the smallest volume ratio J
        and the largest principal strain |λ − 1| over the quadrature points; how far the
        tissue's nodes lie inside the floor and inside the bar (its face, rim or side: every
        node, the penalty contacts' penetration)."""
        grad = field.extract(grad=True, add_identity=True)[0]
        c = np.einsum("kiqc,kjqc->qcij", grad, grad)
        stretch = np.sqrt(np.clip(np.linalg.eigvalsh(c), 0.0, None))
        x = mesh.points[:n_tissue] + u.values[:n_tissue]
        gap = bar_gap(x - (mesh.points[bar_point] + bar.displacement_mm()), axis, problem.radius_mm,
                      problem.edge_radius_mm)[0]
        return {"smallest_jacobian": float(np.linalg.det(np.moveaxis(grad, (0, 1), (-2, -1))).min()),
                "largest_strain": float(np.abs(stretch - 1.0).max()),
                "floor_penetration_mm": float(max(0.0, floor_y - x[:, 1].min())),
                "face_penetration_mm": float(max(0.0, -gap.min()))}

    frames = [measure()]
    saved = [u.values[:n_tissue].copy()]
    advance0 = float(bar.displacement_mm() @ axis)
    advance, force = [0.0], [0.0]
    # the schedule's kinks within the run, and the output times (a kink within round-off of an
    # output time is that time: else both are steps' ends, and the frame is saved twice)
    kinks = sorted(set(times[1:].tolist()) | {float(b) for b in problem.breakpoints_s
                                               if 0 < b < times[-1] and not np.isclose(times, b, rtol=0, atol=1e-9).any()})
    t = 0.0
    for target in kinks:
        while t < target - 1e-12:
            dt = min(s.step_s, target - t)
            for _ in range(s.max_halvings + 1):
                if viscous is not None:
                    viscous.umat.kwargs["dtime_s"] = dt
                inertia.start(dt)
                if driven:
                    # the bar is put where its schedule takes it before Newton starts: given as a
                    # prescribed increment, FElupe's line search judges it by the residual's
                    # linearisation, which knows nothing of the contacts it opens or closes, and
                    # rejected every step once the face had let go of the tissue (a release) or
                    # not yet met it (docs/decisions.md, "A finite-strain truth on FElupe")
                    bar_at = at_rest + float(problem.travel_mm(t + dt)) * axis
                    boundaries["bar"].update(bar_at)
                    u.values[bar_point] = bar_at
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
                  "advance_at_rest_mm": rest + touch + advance0,
                  "smallest_jacobian": min(per_frame["smallest_jacobian"]),
                  "largest_strain": max(per_frame["largest_strain"]),
                  "floor_penetration_mm": max(per_frame["floor_penetration_mm"]),
                  "face_penetration_mm": max(per_frame["face_penetration_mm"]),
                  "frames": per_frame})
    return CreepFESolution(times, displacement, np.asarray(advance), np.asarray(force), stats, p2)


__all__ = ["FiniteStrainSettings", "bar_gap", "finite_strain_reference"]
