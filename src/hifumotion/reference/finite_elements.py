"""The finite-element reference: a tissue pressed by a flat bar onto a floor (scikit-fem, TetGen).

The tissue's closed surface is meshed into tetrahedra by TetGen (``tetgen``; quality
bound radius–edge ≤ 1.5, volumes ≤ ``max_volume_mm3``) and solved with **quadratic**
(P2, ten-node) tetrahedra in scikit-fem — a discretisation sharing nothing with the
particle or voxel models it checks: another element, another mesh, boundary-fitted,
another assembler (the direct solver answers to round-off). Small-strain isotropic elasticity (E, ν); gravity
less buoyancy as a body force; the **relaxed limit** of the rheological viscosity (a
Kelvin–Voigt creep under a held force ends where the elastic solid is in equilibrium,
whatever β1, β2).

Contacts (a monotonic push, so contact sets only grow): the floor ``y = 0`` holds every
surface node that reaches it, stuck (no slip: the limit of a rough floor); the bar's
flat end, a disc of ``radius_mm`` moving along ``axis``, holds every surface node under
it that it reaches, stuck to it. The bar's advance δ makes the bar's reaction equal the force (with the contact
sets fixed the solution is affine in δ: two solves per set, then the sets grow). Displacements are from the unloaded
rest shape (gravity and the push together: a body resting on a point has no
gravity-only equilibrium that a linear solver can find; compare models from rest).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hifumotion.physical import STANDARD_GRAVITY_M_S2, TISSUE_DENSITY_KG_M3, WATER_DENSITY_KG_M3
from hifumotion.reference._p2 import MM, spsolve


@dataclass(frozen=True)
class PunchedTissue:
    """The problem, in mm, Pa, N, kg/m³. ``axis`` is the unit direction the bar pushes along."""

    vertices_mm: np.ndarray
    faces: np.ndarray
    youngs_modulus_pa: float
    poisson_ratio: float
    tip_mm: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius_mm: float
    force_n: float
    density_kg_m3: float = TISSUE_DENSITY_KG_M3
    water_density_kg_m3: float = WATER_DENSITY_KG_M3
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2
    max_volume_mm3: float = 2.0


@dataclass
class ReferenceSolution:
    """The push's displacement (mm) at the mesh's P2 nodes, and how it was reached."""

    points_mm: np.ndarray
    displacement_mm: np.ndarray
    advance_mm: float
    force_n: float
    dofs: int
    tetrahedra: int
    iterations: int
    _basis: object = None
    _u_m: np.ndarray | None = None

    def at(self, points_mm: np.ndarray) -> np.ndarray:
        """The displacement (mm) interpolated at ``points_mm`` (P2; nearest node outside the mesh)."""
        from scipy.spatial import cKDTree

        q = np.asarray(points_mm, float).reshape(-1, 3)
        out = np.empty_like(q)
        mesh = self._basis.mesh
        finder = mesh.element_finder()
        try:
            cells = finder(*(q * MM).T)
            ok = cells >= 0
        except ValueError:
            ok = np.zeros(len(q), bool)
        if ok.any():
            # scikit-fem's probes of a vector basis: rows x-components of all points, then y, then z
            values = self._basis.probes((q[ok] * MM).T) @ self._u_m
            out[ok] = values.reshape(3, -1).T / MM
        if (~ok).any():
            _, near = cKDTree(self.points_mm).query(q[~ok])
            out[~ok] = self.displacement_mm[near]
        return out


def punch_reference(problem: PunchedTissue, tolerance: float = 1e-4, max_iterations: int = 60) -> ReferenceSolution:
    """Solve the push of the module docstring; see :class:`ReferenceSolution`."""
    import scipy.sparse as scipy_sparse
    import skfem
    import tetgen
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    p = problem
    tg = tetgen.TetGen(np.asarray(p.vertices_mm, float), np.asarray(p.faces, np.int32))
    nodes, tets = tg.tetrahedralize(order=1, minratio=1.5, maxvolume=p.max_volume_mm3, quality=True)[:2]
    mesh = skfem.MeshTet(np.ascontiguousarray((nodes * MM).T), np.ascontiguousarray(np.asarray(tets, np.int64).T))
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP2()), intorder=4)
    lam, mu = lame_parameters(p.youngs_modulus_pa, p.poisson_ratio)
    stiffness = skfem.asm(linear_elasticity(lam, mu), basis).tocsr()
    weight = (p.density_kg_m3 - p.water_density_kg_m3) * p.gravity_m_s2

    @skfem.LinearForm
    def gravity(v, w):
        return -weight * v[1]

    load = skfem.asm(gravity, basis)
    # a body held at one or two points can still turn about them: a spring 10⁻⁹ of the
    # stiffness on every dof keeps the first contact sets well posed and moves nothing measurable
    regular = 1e-9 * float(stiffness.diagonal().mean()) * scipy_sparse.identity(stiffness.shape[0], format="csr")
    # the P2 nodes (vertices, then edge midpoints) and their three dofs
    dof_xyz = np.concatenate([basis.nodal_dofs.T, basis.edge_dofs.T])  # (points, 3)
    points = basis.doflocs[0, dof_xyz[:, 0]], basis.doflocs[1, dof_xyz[:, 1]], basis.doflocs[2, dof_xyz[:, 2]]
    points = np.stack(points, 1)
    on_surface = np.zeros(len(points), bool)
    surf_dofs = basis.get_dofs(mesh.boundary_facets()).flatten()
    on_surface[np.isin(dof_xyz[:, 0], surf_dofs)] = True
    axis = np.asarray(p.axis, float) / np.linalg.norm(p.axis)
    tip = np.asarray(p.tip_mm, float) * MM
    rel = points - tip
    along0 = rel @ axis
    across = np.linalg.norm(rel - along0[:, None] * axis, axis=1)
    under = on_surface & (across <= p.radius_mm * MM)
    floor_tol = 1e-9 * np.ptp(points[:, 1])

    def solve(floor: np.ndarray, bar: np.ndarray):
        """u = u_0 + δ u_1 with these contact sets: the floor's nodes held at y = 0, the bar's on
        its face at advance δ (both stuck); returns (u_0, u_1, F_0, F_1), the bar's force F_0 + δ F_1."""
        fl, b = np.flatnonzero(floor), np.flatnonzero(bar)
        held = np.unique(np.concatenate([dof_xyz[fl].ravel(), dof_xyz[b].ravel()]))
        free = np.setdiff1d(np.arange(stiffness.shape[0]), held)
        u0 = np.zeros(stiffness.shape[0])
        u1 = np.zeros(stiffness.shape[0])
        u0[dof_xyz[fl, 1]] = -points[fl, 1]
        u0[dof_xyz[b]] = -along0[b][:, None] * axis[None]
        u1[dof_xyz[b]] = axis[None]
        rhs0 = (load - stiffness @ u0)[free]
        rhs1 = (-(stiffness @ u1))[free]
        k_ff = (stiffness[free][:, free] + regular[free][:, free]).tocsr()
        both = spsolve(k_ff, np.stack([rhs0, rhs1], axis=1))
        u0[free], u1[free] = both[:, 0], both[:, 1]
        r0 = stiffness @ u0 - load
        r1 = stiffness @ u1
        return u0, u1, float((r0[dof_xyz[b]] @ axis).sum()), float((r1[dof_xyz[b]] @ axis).sum())

    def contact_at(delta: float, floor: np.ndarray, bar: np.ndarray):
        """The state at bar advance δ: grow both sets from the given ones (from below) until
        nothing crosses the floor or the bar's face; returns (u, force, floor, bar)."""
        floor, bar = floor.copy(), bar.copy()
        for _ in range(max_iterations):
            counter[0] += 1
            u0, u1, f0, f1 = solve(floor, bar)
            u = u0 + delta * u1
            x = points + u[dof_xyz]
            new_floor = on_surface & ~floor & (x[:, 1] < -floor_tol)
            new_bar = under & ~bar & ((x - tip) @ axis < delta - floor_tol)
            if not new_floor.any() and not new_bar.any():
                return u, f0 + delta * f1, floor, bar
            floor |= new_floor
            bar |= new_bar
        raise RuntimeError("the reference's contact sets did not settle")

    counter = [0]
    top = float(along0[under].min())
    floor0 = on_surface & (points[:, 1] <= points[on_surface, 1].min() + floor_tol)
    # bracket the force: the lower end's sets are a subset of every larger advance's
    lo = (top, floor0, under & (along0 <= top + floor_tol), 0.0)
    step = 0.05 * p.radius_mm * MM
    hi = None
    delta = top + step
    while hi is None:
        u, f, fl, br = contact_at(delta, lo[1], lo[2])
        if f < p.force_n:
            lo = (delta, fl, br, f)
            step *= 2.0
            delta = delta + step
        else:
            hi = (delta, f)
    best = (u, f)
    for _ in range(max_iterations):
        if abs(best[1] - p.force_n) <= tolerance * p.force_n:
            break
        # secant between the bracket's ends, kept inside it
        d_lo, f_lo, d_hi, f_hi = lo[0], lo[3], hi[0], hi[1]
        delta = d_lo + (p.force_n - f_lo) * (d_hi - d_lo) / (f_hi - f_lo)
        delta = min(max(delta, d_lo + 0.05 * (d_hi - d_lo)), d_hi - 0.05 * (d_hi - d_lo))
        u, f, fl, br = contact_at(delta, lo[1], lo[2])
        best = (u, f)
        if f < p.force_n:
            lo = (delta, fl, br, f)
        else:
            hi = (delta, f)
    u_final, force = best
    return ReferenceSolution(points / MM, u_final[dof_xyz] / MM, (delta - top) / MM, force, stiffness.shape[0],
                             mesh.t.shape[1], counter[0], basis, u_final)


__all__ = ["PunchedTissue", "ReferenceSolution", "punch_reference"]
